"""Score episodes on a Dask distributed cluster, into the same cache as the local path.

Episodes are the tasks: the scheduler balances them over the workers and, when a worker
dies, runs its episode again elsewhere. Each worker thread builds the matcher once and
keeps it prepared for the last target it saw (worker-local state, see ``_WorkerState``);
a task writes its episode's chunk file atomically into the shared cache, exactly as the
local path does, and the client assembles the final table with the local code. So a
cluster run and a local run resume each other, and the table is the same bytes.

Workers must see the frame-set and the cache at the same absolute paths as the client (a
shared file system) and have the same pin_match, matchers and weights installed; a worker
whose matcher id differs from the client's refuses to write.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pin_match import atomic
from pin_match.contract.matcher import Matcher, MatcherConfig
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.scoring.episode import score_episode

DEFAULT_TIMEOUT_S = 30.0


class DistributedError(PinMatchError, RuntimeError):
    """The cluster cannot do the work: scheduler unreachable, workers lost, workers unlike the client."""


@dataclass(frozen=True)
class MatcherSpec:
    """What a worker needs to build the client's matcher: its class (pickled by reference), its config, its id."""

    cls: type[Matcher]
    cfg: MatcherConfig
    matcher_id: str

    @classmethod
    def of(cls, matcher: Matcher) -> MatcherSpec:
        return cls(type(matcher), matcher.cfg, matcher.id)

    def build(self) -> Matcher:
        matcher = self.cls(self.cfg)
        if matcher.id != self.matcher_id:
            raise DistributedError(f"worker {_worker_name()} builds matcher {matcher.id}, the client "
                                   f"{self.matcher_id}: install the same pin_match, matchers and weights everywhere")
        return matcher


def connect(scheduler: str, *, workers: int | None = None, timeout: float = DEFAULT_TIMEOUT_S) -> Any:
    """A ``distributed.Client``: ``"local"`` starts a cluster of ``workers`` processes here (closed with the
    client); a path to an existing JSON file is a scheduler file; anything else is a scheduler address.

    An unreachable scheduler raises ``DistributedError`` after ``timeout`` seconds. The address goes to
    Dask as given, with no ``security=``: Dask's configured TLS settings (its config files, ``DASK_*``
    variables) apply, so ``tls://`` works from the command line too.
    """
    try:
        from distributed import Client
    except ImportError as exc:
        raise DistributedError("--scheduler needs Dask distributed: pip install 'pin-match[dask]'") from exc
    if scheduler == "local":
        n = workers or min(2, os.cpu_count() or 1)
        threads = str(max(1, (os.cpu_count() or 1) // n))  # the processes share this machine's cores
        return Client(n_workers=n, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0",
                      env={"OMP_NUM_THREADS": threads, "MKL_NUM_THREADS": threads})
    where = dict(scheduler_file=scheduler) if scheduler.endswith(".json") and Path(scheduler).is_file() \
        else dict(address=scheduler)
    try:
        return Client(**where, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        raise DistributedError(f"cannot reach the Dask scheduler {scheduler!r} within {timeout:g} s: {exc}") from exc
    # Dask's own refusals: tls:// with no client certificate configured, tcp:// where its config requires encryption
    except (TypeError, RuntimeError) as exc:
        raise DistributedError(f"Dask refuses to connect to {scheduler!r}: {exc} (Dask's TLS settings: "
                               "docs/distributed.md, section Security)") from exc


def score_episodes(client: Any, fs: FrameSet, matcher: Matcher, episode_ids: list[str], chunks: Path,
                   batch_size: int, bar) -> None:
    """Score every episode without a chunk file as one task each; returns when all chunks exist.

    The first task error stops the run: the remaining tasks are cancelled (chunks already
    written stay, so a rerun resumes) and the error is raised here, naming the episode.
    """
    from concurrent.futures import CancelledError

    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    chunks, root = Path(chunks).resolve(), Path(fs.root).resolve()
    frames = fs.frames.episode_id.value_counts()
    todo = []
    for episode_id in episode_ids:
        if (chunks / f"{episode_id}.parquet").exists():
            bar.update(int(frames.get(episode_id, 0)))
        else:
            todo.append(episode_id)
    # episodes of one target next to each other, so a worker often keeps its prepared target
    targets = fs.episodes.set_index("episode_id").target_object_id
    todo.sort(key=lambda e: (str(targets[e]), e))
    spec = MatcherSpec.of(matcher)
    futures = {client.submit(_score_task, str(root), fs.fingerprint, spec, e, str(chunks / f"{e}.parquet"),
                             batch_size, key=f"pin-match-{matcher.id}-{e}-{_token(chunks, batch_size)}"): e
               for e in todo}
    try:
        for future in as_completed(futures):
            try:
                n = future.result()  # re-raises the task's own error, e.g. MatcherError naming the frames
            except KilledWorker as exc:
                raise DistributedError(f"episode {futures[future]!r} killed every worker that ran it; "
                                       f"out of memory? ({exc})") from exc
            except CancelledError as exc:
                raise DistributedError(f"episode {futures[future]!r} was cancelled, the scheduler lost? ({exc}); "
                                       f"the chunks written so far are kept: rerun to resume") from exc
            bar.update(n)
    finally:
        client.cancel(list(futures))


def _token(chunks: Path, batch_size: int) -> str:
    from dask.base import tokenize

    return tokenize(str(chunks), batch_size)[:10]


def _score_task(root: str, fingerprint: str, spec: MatcherSpec, episode_id: str, chunk: str, batch_size: int) -> int:
    """On a worker: score one episode into its chunk file (unless it exists); returns the episode's frame count."""
    import pyarrow.parquet as pq

    path = Path(chunk)
    if path.exists():  # written meanwhile by another run on the same cache
        return pq.read_metadata(path).num_rows
    state = _STATE.for_matcher(spec)
    fs = _frameset(root, fingerprint)
    rows = score_episode(fs, state.matcher, episode_id, batch_size=batch_size, pool=state.pool, held=state.held)
    atomic.write_parquet(path, rows)
    return len(rows)


class _WorkerState(threading.local):
    """Per worker thread: the matcher built once, the target it holds, a pool that decodes frames ahead.

    Thread-local because ``prepare`` changes the matcher: two tasks on one worker's threads
    never share one. A new matcher id (the next run on a long-lived cluster) replaces it.
    """

    def __init__(self) -> None:
        self.pool = ThreadPoolExecutor(max_workers=2)
        self.matcher_id: str | None = None
        self.matcher: Matcher | None = None
        self.held: dict[str, str] = {}

    def for_matcher(self, spec: MatcherSpec) -> _WorkerState:
        if self.matcher_id != spec.matcher_id:
            self.matcher_id, self.matcher, self.held = None, None, {}
            self.matcher = spec.build()
            self.matcher_id = spec.matcher_id
        return self


_STATE = _WorkerState()
_FRAMESETS: dict[str, FrameSet] = {}
_FRAMESETS_LOCK = threading.Lock()


def _frameset(root: str, fingerprint: str) -> FrameSet:
    """The frame-set, loaded once per worker process, checked to be the client's."""
    with _FRAMESETS_LOCK:
        key = f"{root}\0{fingerprint}"
        if key not in _FRAMESETS:
            fs = FrameSet.load(root)
            if fs.fingerprint != fingerprint:
                raise DistributedError(f"worker {_worker_name()} sees a different frame-set at {root} "
                                       f"(fingerprint {fs.fingerprint}, the client's {fingerprint})")
            _FRAMESETS.clear()
            _FRAMESETS[key] = fs
        return _FRAMESETS[key]


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return f"pid {os.getpid()}"
