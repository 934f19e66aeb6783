"""Where runs execute: a local process pool, or a Ray cluster (imported only when asked for).

Both take the same run specs and hand each finished row to `on_result` as soon as it arrives
(in completion order, which differs between backends and between executions; the results
file is sorted by run key at the end, so the same specs give the same file whichever ran them).
Every run executes in a worker process with one torch thread (runner.run_in_worker).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

from dfa_viz.experiment.runner import RunSpec, Settings, init_worker, run_in_worker
from sim.core import UserError

BACKENDS = ("local", "ray")
OnResult = Callable[[dict[str, object]], None]


def run_local(
    specs: Sequence[RunSpec], settings: Settings, *, workers: int, on_result: OnResult
) -> int:
    """Run every spec on a pool of `workers` fresh (spawned) processes; returns how many ran.

    Specs are submitted in order, at most 2 x workers at a time, so that the runs of one task
    tend to land on a worker that has already prepared it.
    """
    if workers < 1:
        raise UserError(f"--workers must be at least 1, not {workers}")
    if not specs:
        return 0
    ctx = multiprocessing.get_context("spawn")  # no fork after torch, EGL or MuJoCo started
    todo = list(specs)
    done = 0
    pool = ProcessPoolExecutor(workers, mp_context=ctx, initializer=init_worker)
    try:
        running: set = set()
        while todo or running:
            while todo and len(running) < 2 * workers:
                running.add(pool.submit(run_in_worker, todo.pop(0), settings))
            finished, running = wait(running, return_when=FIRST_COMPLETED)
            for fut in finished:
                on_result(fut.result())
                done += 1
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)  # an error or Ctrl-C: stop, keep rows
        raise
    pool.shutdown()
    return done


def run_ray(
    specs: Sequence[RunSpec],
    settings: Settings,
    *,
    workers: int,
    on_result: OnResult,
    address: str | None = None,
) -> int:
    """Run every spec as a Ray task (one CPU each); returns how many ran.

    address: an existing cluster ("auto" or "ray://host:port"); None starts a local Ray
        instance with `workers` CPUs on this machine (and stops it afterwards). When Ray is
        already initialised in this process, that instance is used and left running.
    Each node needs the project installed and its base policies cached (or it trains them,
    deterministically, on first use).
    """
    try:
        import ray
    except ImportError:
        raise UserError(
            "--backend ray needs Ray: pip install 'dfa[ray]' (or pip install 'ray>=2.9')"
        ) from None
    if workers < 1:
        raise UserError(f"--workers must be at least 1, not {workers}")
    if not specs:
        return 0
    started = False
    if not ray.is_initialized():
        env = {k: os.environ[k] for k in ("MUJOCO_GL", "DFA_CACHE") if k in os.environ}
        ray.init(
            address=address,
            num_cpus=workers if address is None else None,
            include_dashboard=False,
            log_to_driver=False,
            runtime_env={"env_vars": env} if env else None,
        )
        started = True
    try:
        task = ray.remote(num_cpus=1, max_retries=2)(run_in_worker)
        settings_ref = ray.put(settings)
        pending = [task.remote(spec, settings_ref) for spec in specs]
        done = 0
        while pending:
            finished, pending = ray.wait(pending, num_returns=1)
            on_result(ray.get(finished[0]))
            done += 1
        return done
    finally:
        if started:
            ray.shutdown()


def run_specs(
    specs: Sequence[RunSpec],
    settings: Settings,
    *,
    backend: str,
    workers: int,
    on_result: OnResult,
    ray_address: str | None = None,
) -> int:
    """Dispatch to a backend by name; returns how many runs executed."""
    if backend == "local":
        return run_local(specs, settings, workers=workers, on_result=on_result)
    if backend == "ray":
        return run_ray(specs, settings, workers=workers, on_result=on_result, address=ray_address)
    raise UserError(f"unknown backend {backend!r}; accepted: {', '.join(BACKENDS)}")
