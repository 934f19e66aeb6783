"""Where many independent jobs execute: a local process pool, or a Ray cluster (imported only
when asked for). The finetuning experiment and the sweep both run on these.

A job is `fn(item, shared)` for a module-level `fn` (it travels to the worker by name); each
finished result goes to `on_result` as soon as it arrives, in completion order, which differs
between backends and between executions: callers put results in order by their own keys, so
the same items give the same output whichever backend ran them. Every job runs with one torch
thread (`init_worker`): results must not depend on the thread count, and parallelism comes
from running jobs side by side.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from sim.core import UserError

BACKENDS = ("local", "ray")
Job = Callable[[Any, Any], Any]  # (item, shared) -> result
OnResult = Callable[[Any], None]


def init_worker() -> None:
    """A worker's set-up: headless MuJoCo, one torch thread."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import torch

    torch.set_num_threads(1)


def init_pool_worker() -> None:
    """A local pool's worker: init_worker, and an end when the process that started it ends
    (killed, say: the pool's queue would never tell the worker, which would wait forever)."""
    init_worker()
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, name="dfa-parent-watch", daemon=True).start()


def run_job(fn: Job, item: Any, shared: Any) -> Any:
    """What a backend ships to a worker: the set-up, then the job."""
    init_worker()
    return fn(item, shared)


@contextlib.contextmanager
def one_torch_thread() -> Iterator[None]:
    """Run the block with one torch thread (as every worker does), then restore the count."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def _check_workers(workers: int) -> None:
    if workers < 1:
        raise UserError(f"--workers must be at least 1, not {workers}")


def run_local(
    fn: Job,
    items: Sequence[Any],
    shared: Any,
    *,
    workers: int,
    on_result: OnResult,
    in_process: bool = False,
) -> int:
    """Run every item on a pool of `workers` fresh (spawned) processes; returns how many ran.

    Items are submitted in order, at most 2 x workers at a time, so that neighbouring items
    (e.g. the runs of one task) tend to land on a worker that has already prepared them.
    in_process: with one worker, run the items here instead (one torch thread, as in a
        worker), sparing the start of a process when the work is short.
    """
    _check_workers(workers)
    if not items:
        return 0
    if in_process and workers == 1:
        os.environ.setdefault("MUJOCO_GL", "egl")
        with one_torch_thread():
            for item in items:
                on_result(fn(item, shared))
        return len(items)
    ctx = multiprocessing.get_context("spawn")  # no fork after torch, EGL or MuJoCo started
    todo = list(items)
    done = 0
    pool = ProcessPoolExecutor(workers, mp_context=ctx, initializer=init_pool_worker)
    try:
        running: set = set()
        while todo or running:
            while todo and len(running) < 2 * workers:
                running.add(pool.submit(fn, todo.pop(0), shared))
            finished, running = wait(running, return_when=FIRST_COMPLETED)
            for fut in finished:
                on_result(fut.result())
                done += 1
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)  # an error or Ctrl-C: stop, keep results
        raise
    pool.shutdown()
    return done


RAY_LOOPBACK = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
"""Ray's own switch (read when ray is imported): "0" keeps every address Ray gives this
machine's nodes and driver at 127.0.0.1, where it binds its servers to loopback only. Without
it Ray 2.60 swaps 127.0.0.1 and localhost, given as a node's or a cluster's address, for the
machine's routable address, and binds to every interface."""


def on_loopback(address: str | None) -> bool:
    """Whether Ray should stay on 127.0.0.1: an instance started here (None), or a cluster
    reached at a loopback address (127.x.x.x, localhost)."""
    if address is None:
        return True
    host = address.removeprefix("ray://").rpartition(":")[0].strip("[]")
    return host == "localhost" or host.startswith("127.")


def run_ray(
    fn: Job,
    items: Sequence[Any],
    shared: Any,
    *,
    workers: int,
    on_result: OnResult,
    address: str | None = None,
) -> int:
    """Run every item as a Ray task (one CPU each); returns how many ran.

    address: an existing cluster (its head's "host:port", "auto" or "ray://host:port"); None
        starts a local Ray instance with `workers` CPUs on this machine, bound to 127.0.0.1
        (and stops it afterwards). When Ray is already initialised in this process, that
        instance is used and left running.
    Each node needs the project installed and its base policies cached (or it trains them,
    deterministically, on first use).
    """
    _check_workers(workers)
    if not items:
        return 0
    with ray_instance(workers, address) as ray:
        task = ray.remote(num_cpus=1, max_retries=2)(run_job)
        shared_ref = ray.put(shared)
        pending = [task.remote(fn, item, shared_ref) for item in items]
        done = 0
        while pending:
            finished, pending = ray.wait(pending, num_returns=1)
            on_result(ray.get(finished[0]))
            done += 1
        return done


@contextlib.contextmanager
def ray_instance(workers: int, address: str | None = None) -> Iterator[Any]:
    """Ray, initialised for the block (the `ray` module): joined to the cluster at `address`,
    or a local instance with `workers` CPUs bound to 127.0.0.1 (see RAY_LOOPBACK), shut down
    afterwards; already initialised in this process: that instance, left running."""
    if on_loopback(address) and "ray" not in sys.modules:
        os.environ.setdefault(RAY_LOOPBACK, "0")
    try:
        import ray
    except ImportError:
        raise UserError(
            "--backend ray needs Ray: pip install 'dfa[ray]' (or pip install 'ray>=2.9')"
        ) from None
    if ray.is_initialized():
        yield ray
        return
    env = {k: os.environ[k] for k in ("MUJOCO_GL", "DFA_CACHE") if k in os.environ}
    ray.init(
        address=address,
        num_cpus=workers if address is None else None,
        include_dashboard=False,
        log_to_driver=False,
        runtime_env={"env_vars": env} if env else None,
    )
    try:
        yield ray
    finally:
        ray.shutdown()


def run_all(
    fn: Job,
    items: Sequence[Any],
    shared: Any,
    *,
    backend: str,
    workers: int,
    on_result: OnResult,
    ray_address: str | None = None,
    in_process: bool = False,
) -> int:
    """Dispatch to a backend by name; returns how many items ran."""
    if backend == "local":
        return run_local(
            fn, items, shared, workers=workers, on_result=on_result, in_process=in_process
        )
    if backend == "ray":
        return run_ray(fn, items, shared, workers=workers, on_result=on_result, address=ray_address)
    raise UserError(f"unknown backend {backend!r}; accepted: {', '.join(BACKENDS)}")
