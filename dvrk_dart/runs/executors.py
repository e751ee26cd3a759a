"""Where a batch's independent tasks run: a local process pool (the default)
or a Ray cluster (`--executor ray`, `--ray-address ADDR`; without an address a
local Ray instance with `jobs` CPUs is started and shut down afterwards).

`run_tasks(fn, tasks, ...)` calls fn(task) for every task and yields
(task, result, error) as they finish, with a progress bar. A task that raises
is reported with its error; the others go on. Results travel back to the
driver, which writes every output: Ray workers need not share its file system.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed

from dvrk_dart.errors import DvrkDartError

EXECUTORS = ("local", "ray")


#: Linux's prctl option: a signal the process gets when its parent dies
PR_SET_PDEATHSIG = 1


def quiet_worker() -> None:
    """A pool worker's start: Ctrl-C is the main process's to handle (it ends
    the pool), a worker it ends stops at once, without a traceback, removing
    the folder it was building, and a worker whose parent died (a pool inside a
    pool worker) dies with it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _end_worker)
    with contextlib.suppress(OSError, AttributeError):  # not Linux: the pool's own shutdown ends it
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


class _WorkerEnded(BaseException):
    """SIGTERM in a worker's task: raised through the task's finally blocks (not an Exception: no task catches it)."""


def _end_worker(signum, _frame) -> None:
    """SIGTERM in a worker: inside a task, the task's finally blocks run first (a half-built output folder is
    removed; the default action left it behind a command that said "partial outputs removed")."""
    if not _in_task:
        os._exit(128 + signum)
    raise _WorkerEnded


def _in_worker(fn: Callable, task):
    """A task in a pool worker, which ends the process once an ended task has cleaned up."""
    global _in_task
    _in_task = True
    try:
        return fn(task)
    except _WorkerEnded:
        os._exit(128 + signal.SIGTERM)
    finally:
        _in_task = False


_in_task = False
#: how long the main process waits for ended workers to remove what they were building (s)
WORKER_CLEANUP_S = 10.0

#: how long a Ray head may take to accept a connection before the address is called unreachable (s)
RAY_CONNECT_TIMEOUT_S = 5.0


def check_ray_address(address: str | None) -> None:
    """Ray is installed and a Ray head is listening at HOST:PORT (or ray://HOST:PORT): checked in
    seconds, before any work (ray.init itself retries for minutes)."""
    import importlib.util
    import socket

    if importlib.util.find_spec("ray") is None:  # a dependency of the project: only a broken install lands here
        raise DvrkDartError("--executor ray: the ray package is not installed")
    if not address or address == "auto":
        return
    target = address.split("://", 1)[-1]
    host, _, port = target.rpartition(":")
    if not host or not port.isdigit():
        raise DvrkDartError(f"--ray-address {address!r}: expected HOST:PORT (e.g. 10.0.0.5:6379)")
    try:
        with socket.create_connection((host, int(port)), timeout=RAY_CONNECT_TIMEOUT_S):
            pass
    except OSError as exc:
        raise DvrkDartError(f"--ray-address {address!r}: no Ray head answers there ({exc.strerror or type(exc).__name__})") from None


def error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}".splitlines()[0]


@contextlib.contextmanager
def _ray(jobs: int, address: str | None):
    try:
        import ray
    except ImportError:  # a dependency of the project: only a broken install lands here
        raise DvrkDartError("--executor ray: the ray package is not installed") from None
    started = not ray.is_initialized()
    if started:
        check_ray_address(address)
        try:
            if address:
                ray.init(address=address, log_to_driver=False)
            else:
                ray.init(num_cpus=max(1, jobs), include_dashboard=False, log_to_driver=False)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            raise DvrkDartError(f"--ray-address: cannot connect to Ray at {address!r} ({error_text(exc)})") from None
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()


def _stop(pool: ProcessPoolExecutor, finished: bool) -> None:
    """Shut the pool down; interrupted (Ctrl-C, an error of the caller), at once:
    queued tasks cancelled and running workers ended, not waited for."""
    if finished:
        pool.shutdown(wait=True)
        return
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:  # their half-built folders removed before the command says so
        process.join(timeout=WORKER_CLEANUP_S)


def run_tasks(fn: Callable, tasks: Sequence, executor: str = "local", jobs: int = 2, ray_address: str | None = None,
              desc: str = "runs", unit: str = "run") -> Iterator[tuple[object, object, str | None]]:
    """(task, result, None) or (task, None, error) for each task, as they finish."""
    from tqdm import tqdm

    if executor not in EXECUTORS:
        raise DvrkDartError(f"--executor: '{executor}' is not one of {', '.join(EXECUTORS)}")
    if not tasks:
        return
    # a bar on a terminal only, cleared when done or interrupted: stderr keeps the one-line messages
    with tqdm(total=len(tasks), desc=desc, unit=unit, leave=False, disable=None) as bar:
        if executor == "local":
            pool = ProcessPoolExecutor(max_workers=max(1, min(jobs, len(tasks))), initializer=quiet_worker)
            finished = False
            try:
                futures = {pool.submit(_in_worker, fn, task): task for task in tasks}
                for future in as_completed(futures):
                    try:
                        yield futures[future], future.result(), None
                    except Exception as exc:  # one failed task must not stop the batch
                        yield futures[future], None, error_text(exc)
                    bar.update()
                finished = True
            finally:
                _stop(pool, finished)
            return
        with _ray(jobs, ray_address) as ray:
            remote = ray.remote(fn)
            pending = {remote.remote(task): task for task in tasks}
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                task = pending.pop(done[0])
                try:
                    yield task, ray.get(done[0]), None
                except Exception as exc:  # RayTaskError wraps the task's own exception
                    cause = getattr(exc, "cause", None) or exc
                    yield task, None, error_text(cause)
                bar.update()
