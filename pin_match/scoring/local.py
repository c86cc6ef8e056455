"""Score episodes in this process, taking turns with other processes on the same cache through lock files.

Each episode's rows land in their own chunk file per job, written atomically, so a killed run
resumes where it stopped (a damaged chunk is scored again) and two processes can share one cache.
"""

from __future__ import annotations

import errno
import os
import time
from collections.abc import Sequence
from pathlib import Path

from pin_match import atomic
from pin_match.contract.matcher import Matcher
from pin_match.data.frameset import FrameSet
from pin_match.scoring.episode import Output, PreparedMatchers, score_into_chunks

LOCK_STALE_S = 600.0
LOCK_EMPTY_S = 5.0  # a lock still without a pid after this long was left by a process killed while taking it


def score_here(part: FrameSet, matchers: Sequence[Matcher], outputs: Sequence[Output], episode_ids: list[str],
               batch_size: int, workers: int, bar) -> None:
    """Score the episodes without sound chunks in this process, taking turns with other processes through lock
    files (one per job and episode, all taken or none); the chunks are looked at under the locks, so an episode
    another process just finished is not scored again."""
    with PreparedMatchers(matchers, workers) as prepared:
        pending = list(episode_ids)
        while pending:
            deferred = []
            for episode_id in pending:
                locks = _lock_all([out.chunks / f"{episode_id}.lock" for out in outputs])
                if locks is None:  # another process is scoring it right now
                    deferred.append(episode_id)
                    continue
                try:
                    score_into_chunks(part, prepared, outputs, episode_id, batch_size=batch_size, bar=bar)
                finally:
                    for lock in locks:
                        lock.unlink(missing_ok=True)
            if deferred:
                time.sleep(0.2)
            pending = deferred


def _lock_all(paths: list[Path]) -> list[Path] | None:
    """Every lock, or none of them (those taken are let go when one is held elsewhere)."""
    taken = []
    for path in paths:
        lock = _try_lock(path)
        if lock is None:
            for held in taken:
                held.unlink(missing_ok=True)
            return None
        taken.append(lock)
    return taken


def _try_lock(path: Path) -> Path | None:
    """An exclusive per-episode lock file; a lock older than LOCK_STALE_S or of a dead pid is taken over."""
    for _ in range(2):
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            if _lock_is_stale(path):
                path.unlink(missing_ok=True)
                continue
            return None
        except OSError as exc:
            if exc.errno in (errno.EROFS, errno.EACCES, errno.ENOSPC):
                raise atomic.OutputError(f"cannot write into {path.parent}: {exc.strerror}") from exc
            raise
        with os.fdopen(fd, "w") as fh:
            fh.write(str(os.getpid()))
        return path
    return None


def _lock_is_stale(path: Path) -> bool:
    try:
        text = path.read_text()
        age = time.time() - path.stat().st_mtime
        pid = int(text or "0")
    except (OSError, ValueError):
        return True
    if age > LOCK_STALE_S:
        return True
    if pid <= 0:  # its writer is between creating it and writing the pid, or was killed there
        return age > LOCK_EMPTY_S
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False
