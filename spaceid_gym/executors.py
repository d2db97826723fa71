"""One pluggable way to run independent jobs: in this process, in local worker processes, or on a Dask cluster.

``spaceid evaluate``, ``spaceid diagnose-suite`` and ``spaceid arm cross-validate`` hand their jobs (one setting,
one log, one held-out movement) to :func:`run_jobs`, whose :class:`ExecutorSpec` says where they run:

* ``serial``: one after the other in this process;
* ``processes``: a :class:`~concurrent.futures.ProcessPoolExecutor` of ``jobs`` local
  worker processes (default: every core, ``os.cpu_count()``);
* ``dask``: a Dask distributed cluster, the scheduler at ``scheduler`` (``tcp://host:8786``; its workers must have
  this package installed) or, without one, a :class:`distributed.LocalCluster` of ``jobs`` single-threaded worker
  processes started for the run and closed after it. Dask is an optional extra (``pip install
  spaceid-gym[dask]``); without it this executor raises a :class:`~spaceid_gym.errors.SpaceIdInputError` that says
  so.

On the command line (:func:`add_executor_arguments`): ``--executor {serial,processes,dask} --jobs N --scheduler
ADDRESS``; without ``--executor``, ``processes`` when ``--jobs`` is given (as ``--jobs`` alone always meant) and
``serial`` otherwise.

Reproducibility: a job's result depends on the job alone. A job carries everything random it needs (the seeds of
its simulation and of its estimators); where a command needs a seed per job it takes it from
:func:`job_seeds` (``numpy.random.SeedSequence(seed).spawn(n)``), never from a worker's state or from the order
of completion. Every job runs with its BLAS and OpenMP pools limited to one thread (threadpoolctl), so matrix
products sum in the same order in this process and in any worker, and the serial executor too hands each job the
copy a worker would receive (pickled and unpickled: a strided view arrives as a contiguous array, which BLAS sums
in another order in its last bits); the results come back in the jobs' order.
The results are therefore bit-identical whatever the executor and the number of workers (``tests/test_executors.py``
holds that on a tiny job set).

Progress: a :mod:`tqdm` bar counts completed jobs. Cancel: Ctrl-C (``KeyboardInterrupt``) cancels the jobs not
started, stops the workers and propagates; the commands write their outputs only after every job is done, each
file atomically (written to a temporary name, then renamed), so a cancelled run leaves no half-written file.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from spaceid_gym.errors import SpaceIdInputError

#: the executors' names, in the ``--executor`` option's order
EXECUTORS = ("serial", "processes", "dask")

#: what :class:`ExecutorSpec` is without a kind (the commands: see :func:`executor_from_arguments`)
DEFAULT_EXECUTOR = "serial"

#: the message when Dask is missing
DASK_MISSING = (
    "--executor dask: Dask is not installed; install the optional extra with "
    "'pip install \"spaceid-gym[dask]\"' (dask[distributed]), or use --executor processes"
)

Item = TypeVar("Item")
Result = TypeVar("Result")


@dataclass(frozen=True)
class ExecutorSpec:
    """Where jobs run (see the module docstring).

    Attributes:
        kind: ``serial``, ``processes`` or ``dask``.
        jobs: worker processes (``processes``; ``dask`` without a scheduler: the LocalCluster's workers);
            ``None``: every core. Not used by ``serial`` or by a given Dask scheduler.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``); only with ``dask``.
    """

    kind: str = DEFAULT_EXECUTOR
    jobs: int | None = None
    scheduler: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in EXECUTORS:
            raise SpaceIdInputError(f"--executor: expected one of {', '.join(EXECUTORS)}, got {self.kind!r}")
        if self.jobs is not None and (isinstance(self.jobs, bool) or not isinstance(self.jobs, int) or self.jobs < 1):
            raise SpaceIdInputError(f"--jobs: expected an integer >= 1, got {self.jobs!r}")
        if self.scheduler is not None and self.kind != "dask":
            raise SpaceIdInputError(f"--scheduler: a Dask scheduler's address, only with --executor dask (not {self.kind})")
        if self.scheduler is not None and not self.scheduler.strip():
            raise SpaceIdInputError("--scheduler: expected an address such as tcp://host:8786, got an empty string")

    @property
    def workers(self) -> int:
        """The local workers this spec starts: 1 for ``serial``, ``jobs`` or every core otherwise (0 for a given Dask
        scheduler: its workers are the cluster's)."""
        if self.kind == "serial":
            return 1
        if self.scheduler is not None:
            return 0
        return self.jobs if self.jobs is not None else (os.cpu_count() or 1)

    def describe(self) -> str:
        """E.g. ``processes (2 workers)``, ``dask (tcp://host:8786)``, ``dask (LocalCluster, 2 workers)``, ``serial``."""
        if self.kind == "serial":
            return "serial"
        if self.scheduler is not None:
            return f"dask ({self.scheduler})"
        where = "LocalCluster, " if self.kind == "dask" else ""
        return f"{self.kind} ({where}{self.workers} worker{'s' if self.workers != 1 else ''})"


def job_seeds(seed: int, n_jobs: int) -> list[int]:
    """One seed per job (n_jobs,): the first 32-bit word of each child of ``numpy.random.SeedSequence(seed).spawn(n_jobs)``.

    Independent streams for any number of jobs, and job ``i``'s seed does not depend on ``n_jobs``' other jobs'
    order of execution (only on ``seed`` and ``i``)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SpaceIdInputError(f"seed: expected an integer >= 0, got {seed!r}")
    return [int(child.generate_state(1)[0]) for child in np.random.SeedSequence(int(seed)).spawn(n_jobs)]


def _single_threaded(function: Callable[[Any], Any], item: Any) -> Any:
    """``function(item)`` with BLAS/OpenMP limited to one thread (the same summation order in any process)."""
    with threadpool_limits(limits=1):
        return function(item)


def run_jobs(
    function: Callable[[Item], Result],
    items: Sequence[Item],
    executor: ExecutorSpec | None = None,
    *,
    desc: str = "jobs",
    unit: str = "job",
    progress: bool = True,
) -> list[Result]:
    """``[function(item) for item in items]`` on ``executor`` (default: serial, in this process), in the items'
    order, with a progress bar; see the module docstring.

    ``function`` and the items must be picklable (a module-level function) for ``processes`` and ``dask``. An
    exception in a job propagates (the jobs not started are cancelled); so does a ``KeyboardInterrupt``.
    """
    spec = executor or ExecutorSpec()
    items = list(items)
    if not items:
        return []
    with tqdm(total=len(items), desc=desc, unit=unit, disable=not progress) as bar:
        return list(_RUNNERS[spec.kind](function, items, spec, bar))


def _run_serial(function: Callable[[Any], Any], items: list[Any], spec: ExecutorSpec, bar: tqdm) -> Iterator[Any]:
    for item in items:
        result = _single_threaded(function, pickle.loads(pickle.dumps(item)))  # the job as a worker receives it
        bar.update()
        yield result


def _run_processes(function: Callable[[Any], Any], items: list[Any], spec: ExecutorSpec, bar: tqdm) -> Iterator[Any]:
    pool = ProcessPoolExecutor(max_workers=min(spec.workers, len(items)))
    try:
        futures = [pool.submit(_single_threaded, function, item) for item in items]
        yield from _in_order(futures, bar)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _in_order(futures: list[Future[Any]], bar: tqdm) -> list[Any]:
    """The futures' results in their order, the bar moved as each completes (a failed job raises at once)."""
    pending = set(futures)
    while pending:
        done, pending = wait(pending, return_when=FIRST_COMPLETED)
        for future in done:
            future.result()  # a job that raised stops the run here
            bar.update()
    return [future.result() for future in futures]


@contextmanager
def _dask_client(spec: ExecutorSpec) -> Iterator[Any]:
    """A connected ``distributed.Client`` (the given scheduler, or a LocalCluster started and closed here)."""
    try:
        # optional dependency, imported only when this executor is asked for
        from distributed import Client, LocalCluster
    except ImportError:
        raise SpaceIdInputError(DASK_MISSING) from None
    if spec.scheduler is not None:
        try:
            client = Client(spec.scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise SpaceIdInputError(f"--scheduler: cannot reach the Dask scheduler at {spec.scheduler!r} ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    # the cluster's nannies set their workers' environment in this process's (OMP_NUM_THREADS=1,
    # OPENBLAS_NUM_THREADS=1, ...) and leave it there: every process started afterwards, by the caller too, would get
    # one BLAS thread, and its arithmetic would differ from this process's in the last bits. Put back as it was
    environment = dict(os.environ)
    try:
        cluster = LocalCluster(n_workers=spec.workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
            cluster.close()
    finally:
        os.environ.clear()
        os.environ.update(environment)


def _run_dask(function: Callable[[Any], Any], items: list[Any], spec: ExecutorSpec, bar: tqdm) -> Iterator[Any]:
    # optional dependency, imported only when this executor is asked for (its absence is reported by _dask_client)
    with _dask_client(spec) as client:
        from distributed import as_completed

        futures = client.map(_single_threaded, [function] * len(items), items, pure=False)
        try:
            for future in as_completed(futures):
                future.result()  # a job that raised stops the run here
                bar.update()
            results = client.gather(futures)
        except BaseException:
            client.cancel(futures)
            raise
    yield from results


_RUNNERS: dict[str, Callable[[Callable[[Any], Any], list[Any], ExecutorSpec, tqdm], Iterator[Any]]] = {
    "serial": _run_serial,
    "processes": _run_processes,
    "dask": _run_dask,
}


def add_executor_arguments(parser: Any) -> None:
    """``--executor {serial,processes,dask}``, ``--jobs N`` and ``--scheduler ADDRESS`` on an argparse parser."""
    parser.add_argument(
        "--executor",
        choices=EXECUTORS,
        default=None,
        help="where the independent jobs run: serial (this process), processes (local worker processes), dask (a Dask "
        "cluster: --scheduler, or a LocalCluster started for the run; optional extra 'dask') (default: processes with "
        "--jobs, else serial)",
    )
    parser.add_argument(
        "--jobs", type=int, default=None, help="worker processes of processes or of a Dask LocalCluster (default: every core)"
    )
    parser.add_argument(
        "--scheduler", default=None, metavar="ADDRESS", help="address of a running Dask scheduler, e.g. tcp://host:8786"
    )


def executor_from_arguments(args: Any, max_jobs: int) -> ExecutorSpec:
    """The :class:`ExecutorSpec` of parsed ``--executor``, ``--jobs`` and ``--scheduler`` (``--jobs`` at most
    ``max_jobs``); without ``--executor``: ``processes`` with ``--jobs``, ``dask`` with ``--scheduler``, else ``serial``."""
    jobs = args.jobs
    if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, int) or not 1 <= jobs <= max_jobs):
        raise SpaceIdInputError(f"--jobs: expected an integer from 1 to {max_jobs}, got {jobs!r}")
    kind = args.executor or ("dask" if args.scheduler is not None else "processes" if jobs is not None else "serial")
    if kind == "serial" and jobs is not None and jobs > 1:
        raise SpaceIdInputError(f"--jobs {jobs}: the serial executor runs in this process; use --executor processes or dask")
    return ExecutorSpec(kind, jobs, args.scheduler)
