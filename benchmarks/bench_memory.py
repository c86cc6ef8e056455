"""Peak memory of scoring 1,000 vs 10,000 frames: streaming keeps it flat.

Each run is a fresh subprocess (so earlier runs do not count) scoring a procedural
frame-set with ``color`` (about 1,150 candidate points per frame stored in the table);
the peak resident set size is the child's own high-water mark (VmHWM).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile

from benchmarks.framesets import procedural

# VmHWM, not ru_maxrss: the latter survives exec and would report the parent's peak
CHILD = """
import sys
from pin_match.scoring import RunOptions, score_to_file
score_to_file(sys.argv[1], "color", out=sys.argv[2], run=RunOptions(workers=2, progress=False))
print(next(line.split()[1] for line in open("/proc/self/status") if line.startswith("VmHWM")))
"""


def peak_rss_mb(frameset_root: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        done = subprocess.run([sys.executable, "-c", CHILD, frameset_root, tmp], capture_output=True, text=True,
                              check=True)
    return int(done.stdout.strip().splitlines()[-1]) / 1024.0  # KiB -> MiB


def run(quick: bool = False) -> dict:
    sizes = (100, 1000) if quick else (1000, 10000)
    out = {}
    for n in sizes:
        fs = procedural(n)
        out[f"peak_rss_mb_{n}"] = peak_rss_mb(str(fs.root))
        print(f"scoring {n:6,d} frames with color: peak RSS {out[f'peak_rss_mb_{n}']:.0f} MB")
    out["ratio_large_vs_small"] = out[f"peak_rss_mb_{sizes[1]}"] / out[f"peak_rss_mb_{sizes[0]}"]
    print(f"peak RSS {sizes[1]:,} / {sizes[0]:,} frames = {out['ratio_large_vs_small']:.2f}x (flat = 1.0)")
    return out
