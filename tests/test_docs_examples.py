"""The code in docs/adding-a-matcher.md runs as printed: a newcomer's first matcher passes the contract."""

from __future__ import annotations

import re
from pathlib import Path

DOC = Path(__file__).parents[1] / "docs" / "adding-a-matcher.md"


def test_shortest_matcher_in_the_docs_passes_the_contract():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    assert len(blocks) >= 2
    namespace: dict = {}
    exec(compile("\n".join(blocks[:2]), str(DOC), "exec"), namespace)  # the second block calls check_matcher
    from pin_match.contract.registry import create_matcher

    assert create_matcher("my-matcher").id.startswith("my-matcher@")
