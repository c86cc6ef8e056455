"""Score episodes on a Dask distributed cluster, into the same cache as the local path.

A task is a few consecutive episodes (sorted by target, so one task usually prepares one
target once), enough to amortise a round trip while leaving several tasks per worker for
the scheduler to balance; when a worker dies, its task runs again elsewhere and skips the
episodes whose chunks it already wrote. Before the first task, a worker plugin
(``WorkerSetup``) loads the frame-set and builds one matcher per worker thread, so the
tasks find them ready (``_Matchers``); each task writes every episode's chunk file
atomically into the shared cache, exactly as the local path does, and the client
assembles the final table with the local code. So a cluster run and a local run resume
each other, and the table is the local one: byte for byte where a matcher's arithmetic does not
depend on the thread count (``color``, ``sift``: tests/test_distributed.py compares the files),
within the last bits of a float where a network's sums do (a worker runs ``torch_threads``
threads; the test allows ``rtol=1e-4``, ``atol=1e-5`` on ``verify``'s candidate signals).

Workers must see the frame-set and the cache at the same absolute paths as the client (a
shared file system) and have the same pin_match, matchers and weights installed; a worker
whose matcher id differs from the client's refuses to write.
"""

from __future__ import annotations

import contextlib
import os
import threading
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pin_match.contract.matcher import Matcher, MatcherConfig
from pin_match.data.frameset import FrameSet
from pin_match.errors import PinMatchError
from pin_match.scoring.episode import Output, PreparedMatchers, score_into_chunks

try:  # Dask is optional: without it this module still imports, and ``connect`` says what to install
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError:
    WorkerPlugin = object

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
        return local_cluster(n, torch_threads=max(1, (os.cpu_count() or 1) // n))  # sharing this machine's cores
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


# glibc reads MALLOC_TRIM_THRESHOLD_ once, when a process starts. Dask's nanny sets it for every worker so that
# freed memory goes back to the system; setting it also switches off glibc's adaptive mmap threshold, so every large
# tensor a torch matcher allocates is a fresh mmap, zeroed page by page, which slows torch matchers down
# (measured in docs/performance.md, section "Dask distributed scoring"). Workers started here keep glibc's default.
SLOW_MALLOC_VARIABLE = "MALLOC_TRIM_THRESHOLD_"
_KEEP_GLIBC_DEFAULT = {f"distributed.nanny.pre-spawn-environ.{SLOW_MALLOC_VARIABLE}": None}


def local_cluster(n_workers: int, *, torch_threads: int) -> Any:
    """A client of ``n_workers`` single-thread worker processes on this machine, each with ``torch_threads``
    math threads and glibc's default allocator settings; the dashboard listens on 127.0.0.1 only.

    This process's own value of the variable is not passed on either: an earlier Dask cluster started
    here leaves Dask's value in ``os.environ`` (its nanny writes it there before spawning).
    """
    import dask
    from distributed import Client

    threads = str(torch_threads)
    inherited = os.environ.pop(SLOW_MALLOC_VARIABLE, None)
    try:
        with dask.config.set(_KEEP_GLIBC_DEFAULT):
            return Client(n_workers=n_workers, threads_per_worker=1, processes=True,
                          dashboard_address="127.0.0.1:0", env={"OMP_NUM_THREADS": threads, "MKL_NUM_THREADS": threads})
    finally:
        if inherited is not None:
            os.environ[SLOW_MALLOC_VARIABLE] = inherited


def warn_slow_malloc(client: Any) -> None:
    """Warn when workers run with a trim threshold set: the scores are right, but torch matchers run slower."""
    settings = client.run(_malloc_setting)
    slow = sorted(address for address, value in settings.items() if value is not None)
    if slow:
        warnings.warn(f"{len(slow)} of {len(settings)} Dask workers (e.g. {slow[0]}) run with "
                      f"{SLOW_MALLOC_VARIABLE}={settings[slow[0]]}, Dask's nanny default, which makes torch "
                      f"matchers about 2x slower; start them with it unset (docs/distributed.md, section Speed)",
                      stacklevel=3)


def _malloc_setting() -> str | None:
    return os.environ.get(SLOW_MALLOC_VARIABLE)


TASKS_PER_WORKER = 4  # tasks queued per worker thread: enough for balancing, few enough to amortise round trips


def score_episodes(client: Any, fs: FrameSet, matchers: Sequence[Matcher], outputs: Sequence[Output],
                   episode_ids: list[str], batch_size: int, bar) -> None:
    """Score every episode that lacks a chunk of some job, a few episodes per task; returns when all chunks exist.

    The first task error stops the run: the remaining tasks are cancelled (chunks already
    written stay, so a rerun resumes) and the error is raised here, naming the episodes.
    """
    outputs = tuple(Output(out.product, Path(out.chunks).resolve()) for out in outputs)
    root = Path(fs.root).resolve()
    todo = []
    for episode_id in episode_ids:
        if any(out.done(episode_id) is None for out in outputs):
            todo.append(episode_id)
        else:
            bar.update(int((fs.frames.episode_id == episode_id).sum()))
    if not todo:
        return
    warn_slow_malloc(client)
    specs = tuple(MatcherSpec.of(m) for m in matchers)
    setup = WorkerSetup(specs, str(root), fs.fingerprint)
    threads = sum(client.nthreads().values()) or 1
    token = _token(outputs, batch_size)
    futures: dict = {}
    try:
        client.register_plugin(setup, name=setup.name)  # raises a worker's setup error, e.g. a missing frame-set
        futures = {client.submit(_score_task, str(root), fs.fingerprint, specs, group, outputs, batch_size,
                                 key=f"pin-match-{_ids(specs)}-{group[0]}-{len(group)}-{token}"): group
                   for group in task_groups(todo, fs.episodes.set_index("episode_id").target_object_id, threads)}
        _collect(futures, bar)
    finally:
        if client.status == "running":  # after a lost scheduler there is nobody to tell
            with contextlib.suppress(OSError):  # a connection closing right now is the same case
                client.cancel(list(futures))
                client.unregister_worker_plugin(setup.name)  # workers that join later need not build this run's matcher


def _collect(futures: dict, bar) -> None:
    """Wait for every task; a lost scheduler or killed workers end the run with one DistributedError."""
    from concurrent.futures import CancelledError

    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    group: list[str] = []
    try:
        for future in as_completed(futures):
            group = futures[future]
            bar.update(future.result())  # re-raises the task's own error, e.g. MatcherError naming the frames
    except PinMatchError:
        raise
    except KilledWorker as exc:
        raise DistributedError(f"episodes {_named(group)} killed every worker that ran them; out of memory? "
                               f"({exc})") from exc
    except (CancelledError, OSError) as exc:  # distributed's CommClosedError is an OSError
        raise DistributedError(f"the run was cut off at episodes {_named(group)}: the scheduler lost? "
                               f"({type(exc).__name__}: {exc}); the chunks written so far are kept: rerun to "
                               "resume") from exc


def task_groups(todo: list[str], targets: Any, threads: int) -> list[list[str]]:
    """Episodes sorted by (target, id), cut into runs of at most ``ceil(len / (TASKS_PER_WORKER * threads))``.

    Episodes of one target stay next to each other, so a task (and a worker) usually keeps its
    prepared target; the cap leaves about ``TASKS_PER_WORKER`` tasks per worker thread.
    """
    ordered = sorted(todo, key=lambda e: (str(targets[e]), e))
    size = max(1, -(-len(ordered) // (TASKS_PER_WORKER * max(1, threads))))
    return [ordered[i:i + size] for i in range(0, len(ordered), size)]


def _named(episodes: list[str]) -> str:
    return ", ".join(repr(e) for e in episodes)


def _token(outputs: tuple[Output, ...], batch_size: int) -> str:
    from dask.base import tokenize

    return tokenize([str(out.chunks) for out in outputs], batch_size)[:10]


def _ids(specs: tuple[MatcherSpec, ...]) -> str:
    return "+".join(spec.matcher_id for spec in specs)


def _score_task(root: str, fingerprint: str, specs: tuple[MatcherSpec, ...], episode_ids: list[str],
                outputs: tuple[Output, ...], batch_size: int) -> int:
    """On a worker: score the episodes into their chunk files; returns their frames.

    A sound chunk found is kept: written by an earlier try of this task, or by another run on the
    same cache. A damaged one was named by the client when it submitted the task, so not again here.
    """
    fs = _frameset(root, fingerprint)
    with _MATCHERS.lease(specs) as prepared:
        return sum(score_into_chunks(fs, prepared, outputs, episode_id, batch_size=batch_size, say_why=False)
                   for episode_id in episode_ids)


class _Matchers:
    """Per worker process: built matchers of the current run's matcher ids, lent to one task at a time.

    The worker plugin fills it before the first task (one set per worker thread); a task that finds
    none free builds one. New matcher ids (the next run on a long-lived cluster) replace them.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._ids: str | None = None
        self._free: list[PreparedMatchers] = []

    def fill(self, specs: tuple[MatcherSpec, ...], count: int) -> None:
        with self._lock:
            self._switch(specs)
            missing = count - len(self._free)
        built = [_build(specs) for _ in range(max(0, missing))]
        self._give_back(specs, built)

    @contextmanager
    def lease(self, specs: tuple[MatcherSpec, ...]) -> Iterator[PreparedMatchers]:
        with self._lock:
            self._switch(specs)
            prepared = self._free.pop() if self._free else None
        prepared = prepared or _build(specs)
        try:
            yield prepared
        except BaseException:
            prepared.forget()
            raise
        finally:
            self._give_back(specs, [prepared])

    def _switch(self, specs: tuple[MatcherSpec, ...]) -> None:
        if self._ids != _ids(specs):
            self._ids, self._free = _ids(specs), []

    def _give_back(self, specs: tuple[MatcherSpec, ...], prepared: list[PreparedMatchers]) -> None:
        with self._lock:
            if self._ids == _ids(specs):
                self._free.extend(prepared)


def _build(specs: tuple[MatcherSpec, ...]) -> PreparedMatchers:
    return PreparedMatchers([spec.build() for spec in specs])


_MATCHERS = _Matchers()
_FRAMESETS: dict[str, FrameSet] = {}
_FRAMESETS_LOCK = threading.Lock()


class WorkerSetup(WorkerPlugin):
    """A Dask worker plugin: load the frame-set and build the run's matchers per worker thread before the first task.

    Registered by the client for one run (a worker that joins during the run sets up too) and
    unregistered at its end; its name carries the matcher ids and the frame-set.
    """

    def __init__(self, specs: tuple[MatcherSpec, ...], root: str, fingerprint: str) -> None:
        self.specs, self.root, self.fingerprint = specs, root, fingerprint
        self.name = f"pin-match-setup-{_ids(specs)}-{fingerprint}"

    def setup(self, worker: Any) -> None:
        _frameset(self.root, self.fingerprint)
        _MATCHERS.fill(self.specs, worker.state.nthreads)


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
