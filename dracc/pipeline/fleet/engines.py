"""The fleet's two engines: a local process pool and a Dask distributed scheduler.

Both run :func:`analyse_batch` (several logs per task) and call ``done(task, result)`` in
the parent once per log, as each batch comes back.  A log that fails, or whose analyser
raises, is a failed result of its own; a batch that cannot run at all (its Dask worker
lost, the local pool broken by a dying process) fails the logs it held; Ctrl-C (or
SIGTERM) cancels what is left at once: the local workers are killed (:func:`stop_pool`),
the Dask tasks cancelled.

Batching (issue 20): a small log is a fraction of a second of work, about what Dask
spends scheduling, sending and collecting a task, so :func:`plan_batches` packs the logs
of one folder into tasks of about :data:`BATCH_BYTES`; a larger log stays a task of its
own, and the largest tasks go first.  "Next to its file" means, in dracc, a batch never
mixes folders: the logs of one vessel folder sit on one disk and are read by one
worker one after the other.  dracc does not guess which Dask worker is near which disk:
the workers must see the log paths (a shared disk) and the scheduler places the tasks.

Dask: the :class:`~dracc.core.config.Config` is sent once to every worker
(``Client.scatter(broadcast=True)``) rather than with each task, and :func:`preload`
runs on every worker before the first task (``Client.run``), so no task pays the
imports of the pipeline (0.75 s measured on a fresh process).  The local pool preloads
in the parent (forked workers inherit it) and in each worker it starts (a spawned
worker imports on its own).
"""

from __future__ import annotations

import importlib
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from dracc.core.config import Config
from dracc.core.errors import FleetError
from dracc.core.workers import detach_worker
from dracc.pipeline.fleet.tasks import LogTask

Analyser = Callable[[str, Config], dict]
Done = Callable[[LogTask, dict], None]

#: a batch of small logs is closed when it holds this many bytes (0: one log per task);
#: read at each run, so a benchmark may change it.  benchmarks/bench_fleet.py (2 loaded
#: CPUs, 100 logs of 1-3 MB) found no size from 0 to 8 MB faster beyond the noise
BATCH_BYTES = 4_000_000
#: at least this many tasks per worker where there are enough logs, so that the end of
#: the run is not one worker finishing a long batch while the others wait
TASKS_PER_WORKER = 4

#: what a worker imports before its first task: the pipeline, and the readers and the
#: calibration it would otherwise import during its first analysis
PRELOAD_MODULES = (
    "dracc.pipeline.analysis",
    "dracc.ingest",
    "dracc.ingest.references",
    "dracc.ingest.csv",
    "dracc.ingest.n2k",
    "dracc.ingest.signalk",
    "dracc.ingest.gpsd_json",
    "dracc.ingest.embedded_n2k",
    "dracc.math.calibration",
    "dracc.pipeline.fleet.batch",
)

#: this process as a worker: whether :func:`preload` ran, and whether it had run when
#: the first batch started (see :func:`worker_state`)
_STATE: dict[str, Any] = {"preloaded": False, "preload_s": None, "first_batch_preloaded": None}


def preload() -> dict[str, Any]:
    """Import :data:`PRELOAD_MODULES`; this process's pid and the seconds it took."""
    t0 = time.perf_counter()
    for name in PRELOAD_MODULES:
        try:
            importlib.import_module(name)
        except ImportError:  # pragma: no cover - the analysis reports it per log
            pass
    _STATE["preloaded"] = True
    _STATE["preload_s"] = time.perf_counter() - t0
    return {"pid": os.getpid(), "preload_s": _STATE["preload_s"]}


def worker_state() -> dict[str, Any]:
    """This process as a fleet worker: ``preloaded``, ``preload_s`` and
    ``first_batch_preloaded`` (None before a first batch)."""
    return {"pid": os.getpid(), **_STATE}


def analyse_batch(paths: Sequence[str], cfg: Config, analyser: Analyser) -> list[dict]:
    """Worker: ``analyser(path, cfg)`` for each path, in order; one result per path.

    An analyser that raises gives that log a failed result; the other logs go on.
    """
    if _STATE["first_batch_preloaded"] is None:
        _STATE["first_batch_preloaded"] = _STATE["preloaded"]
    results = []
    for path in paths:
        try:
            results.append(analyser(path, cfg))
        except Exception as err:  # one log's bug must not lose the batch's other logs
            results.append({"ok": False, "error": f"internal error ({type(err).__name__}: {err})"})
    return results


def _bytes(path: str) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def plan_batches(
    todo: Sequence[LogTask], workers: int, batch_bytes: int | None = None
) -> list[list[LogTask]]:
    """The tasks of a run: the logs of one folder packed (first-fit decreasing) into
    batches of at most ``batch_bytes`` (default :data:`BATCH_BYTES`; less when that would
    leave under :data:`TASKS_PER_WORKER` tasks per worker); a log of that size or more
    alone; the largest batch first."""
    limit = BATCH_BYTES if batch_bytes is None else batch_bytes
    size = {t.path: _bytes(t.path) for t in todo}
    # enough tasks to keep every worker busy to the end
    share = sum(size.values()) // max(1, workers * TASKS_PER_WORKER)
    limit = min(limit, share)
    folders: dict[str, list[LogTask]] = {}
    for t in todo:
        folders.setdefault(os.path.dirname(t.path), []).append(t)
    batches: list[list[LogTask]] = []
    for logs in folders.values():
        # first-fit decreasing: each log, largest first, into the first batch with room
        logs.sort(key=lambda t: size[t.path], reverse=True)
        mine: list[list[LogTask]] = []
        held: list[int] = []
        for t in logs:
            room = [i for i, h in enumerate(held) if h + size[t.path] <= limit] if limit > 0 else []
            if room:
                mine[room[0]].append(t)
                held[room[0]] += size[t.path]
            else:
                mine.append([t])
                held.append(size[t.path])
        batches.extend(mine)
    # largest first: the last tasks to finish are short ones (less idle time at the end)
    batches.sort(key=lambda b: sum(size[t.path] for t in b), reverse=True)
    return batches


def _failed(batch: Sequence[LogTask], why: str, done: Done) -> None:
    for task in batch:
        done(task, {"ok": False, "error": why})


def _deliver(batch: Sequence[LogTask], results: object, done: Done) -> None:
    if not isinstance(results, list) or len(results) != len(batch):
        _failed(
            batch, f"the worker gave back {type(results).__name__}, not one result per log", done
        )
        return
    for task, result in zip(batch, results, strict=True):
        done(task, result if isinstance(result, dict) else {"ok": False, "error": repr(result)})


def _local_init(parent_pid: int, warm: bool) -> None:
    detach_worker(parent_pid)
    if warm:  # a no-op in a forked worker (the parent preloaded); a spawned one imports here
        preload()


def run_local(
    todo: Sequence[LogTask],
    cfg: Config,
    workers: int,
    analyser: Analyser,
    done: Done,
    batch_bytes: int | None = None,
) -> None:
    """Analyse ``todo`` on a local process pool of ``workers`` processes."""
    # dracc's own analyser needs the pipeline; a test's stand-in may not
    warm = getattr(analyser, "__module__", "").startswith("dracc.")
    if warm:
        preload()
    batches = plan_batches(todo, workers, batch_bytes)
    with ProcessPoolExecutor(
        max_workers=max(1, min(workers, len(batches))),
        initializer=_local_init,
        initargs=(os.getpid(), warm),
    ) as pool:
        pending: dict[Future, list[LogTask]] = {
            pool.submit(analyse_batch, [t.path for t in b], cfg, analyser): b for b in batches
        }
        try:
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in finished:
                    batch = pending.pop(fut)
                    try:
                        results = fut.result()
                    except BrokenProcessPool as err:
                        _failed(batch, f"worker process died ({err})", done)
                        continue
                    except Exception as err:  # e.g. an analyser or a result that cannot be pickled
                        _failed(batch, f"worker failed ({type(err).__name__}: {err})", done)
                        continue
                    _deliver(batch, results, done)
        except BaseException:  # Ctrl-C, SIGTERM: stop now, not after the running batches
            stop_pool(pool)
            raise


def stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started and kill the worker processes.  A shutdown alone waits
    for the batches the workers run and for those already queued to them (and so does
    the interpreter's exit, joining the pool's thread): after Ctrl-C, as long as a few
    analyses of long logs.  Nothing is lost: a worker writes nothing, the parent has
    cached every result that came back."""
    # the pool forgets its processes at shutdown: take them first
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        try:
            proc.kill()
        except (OSError, ValueError):  # already gone, or closed
            pass


#: at most this long to close the Dask client after an interrupt (default: twice the
#: connect timeout, for a scheduler that does not answer)
_CLOSE_AFTER_INTERRUPT_S = 5.0


def _threads(client: Any) -> int:
    info = client.scheduler_info()
    return max(1, sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()))


def run_dask(
    todo: Sequence[LogTask],
    cfg: Config,
    scheduler: str,
    timeout_s: float,
    analyser: Analyser,
    done: Done,
    batch_bytes: int | None = None,
) -> None:
    """Analyse ``todo`` on the Dask scheduler at ``scheduler`` (its workers see the paths)."""
    try:
        from distributed import Client, as_completed
    except ImportError as err:
        raise FleetError("--scheduler needs Dask distributed: pip install 'dracc[dask]'") from err
    try:
        client = Client(scheduler, timeout=timeout_s, set_as_default=False)
    except (OSError, TimeoutError) as err:
        raise FleetError(f"cannot reach the Dask scheduler at {scheduler}: {err}") from err
    futures: list = []
    try:
        try:
            client.wait_for_workers(1, timeout=timeout_s)
        except TimeoutError as err:
            raise FleetError(
                f"the Dask scheduler at {scheduler} has no workers (waited {timeout_s:g} s)"
            ) from err
        try:  # the imports on every worker at once, before any task
            client.run(preload)
        except Exception:  # only a speed-up: a worker that cannot preload imports on its first task
            pass
        cfg_future = client.scatter(cfg, broadcast=True, hash=False)  # sent once per worker
        batches = plan_batches(todo, _threads(client), batch_bytes)
        by_key: dict[Any, list[LogTask]] = {}
        for i, b in enumerate(batches):
            fut = client.submit(
                analyse_batch,
                [t.path for t in b],
                cfg_future,
                analyser,
                pure=False,
                priority=len(batches) - i,  # largest first
            )
            futures.append(fut)
            by_key[fut.key] = b
        for fut in as_completed(futures, loop=client.loop):
            batch = by_key[fut.key]
            try:
                results = fut.result()
            except Exception as err:  # its worker lost or killed: its logs failed, the rest go on
                _failed(batch, f"dask task failed ({type(err).__name__}: {err})", done)
                continue
            _deliver(batch, results, done)
    except BaseException:
        if futures:
            try:
                client.cancel(futures)
            except Exception:  # pragma: no cover - closing the client releases them anyway
                pass
        client.close(timeout=min(timeout_s, _CLOSE_AFTER_INTERRUPT_S))
        raise
    client.close()
