"""Where a campaign's batches fly: a Dask distributed cluster.

``connect()`` opens a client: on a ``LocalCluster`` of this machine by default (one worker
process per core, one thread each, scheduler and workers on 127.0.0.1 only, no dashboard unless
asked), or on an existing scheduler (``tcp://HOST:PORT``: ``dask scheduler`` and ``dask worker``
on the lab's machines, or dask-jobqueue on SLURM; docs/campaigns.md, "Campaigns on a cluster").
The same code path serves both. A worker whose numpy does not round as the package's processes
do (``geoctl_ros.numpy_rounding_problem``) is refused (``RoundingError``), at the start and by
each task.

``run_tasks()`` submits the tasks, hands each result over as it arrives (nothing is held but what
the caller keeps), and reports progress from the workers' own events: a task calls
``report_progress(fraction)`` now and then. If a worker dies, the scheduler runs its tasks again
on another; each task's result is handed over once, so no task is lost or counted twice.
"""
import contextlib
import logging
import os
import signal
import threading
import time
import uuid

import dask
from distributed import Client, LocalCluster, as_completed, get_worker

from geoctl_ros import RoundingError, numpy_rounding_problem

LOOPBACK = '127.0.0.1'
# Dask's statistical profiler samples the task's stack every 10 ms from the worker's event loop:
# it took 7 % of the batched loop's time (docs/campaigns.md gives the same for `dask worker`)
WORKER_CONFIG = {'distributed.worker.profile.enabled': False}
PROGRESS_TOPIC = 'geoctl-progress'


@contextlib.contextmanager
def connect(scheduler=None, workers=None, dashboard=False):
    """A distributed Client, and a line saying what it runs on; closed (the local cluster shut
    down) on leaving. scheduler: an address (tcp://HOST:PORT) or None for a LocalCluster of
    `workers` processes (default: one per core). dashboard: serve the local cluster's dashboard on
    127.0.0.1:8787.
    """
    if scheduler:
        client = Client(scheduler, timeout='20s')
        try:
            _refuse_foreign_rounding(client)
            yield client, 'scheduler %s (%d workers now)' % (scheduler, worker_count(client))
        finally:
            client.close()
        return
    workers = workers or os.cpu_count() or 1
    with dask.config.set(WORKER_CONFIG):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               host=LOOPBACK, protocol='tcp',
                               dashboard_address='%s:8787' % LOOPBACK if dashboard else None,
                               silence_logs=logging.ERROR)
    try:
        with Client(cluster) as client:
            _refuse_foreign_rounding(client)
            where = 'a local cluster of %d worker processes on %s' % (workers, LOOPBACK)
            if dashboard:
                where += ', dashboard at %s' % client.dashboard_link
            yield client, where
    finally:
        cluster.close()


def _refuse_foreign_rounding(client):
    """RoundingError naming each worker whose numpy does not round as the package's processes
    do, with why (``geoctl_ros.numpy_rounding_problem``): its runs would not be theirs.
    """
    found = client.run(numpy_rounding_problem)
    problems = ['worker %s: %s' % (worker, why) for worker, why in sorted(found.items()) if why]
    if problems:
        raise RoundingError('; '.join(problems))


def checked(fn, task):
    """fn(task) on a worker whose numpy rounds as the package's processes do; else
    RoundingError with why (a worker that joined after ``connect``'s check). Every task of the
    tools goes through it (``run_tasks``, or ``functools.partial(checked, fn)`` to ``map``).
    """
    problem = numpy_rounding_problem()
    if problem:
        raise RoundingError(problem)
    return fn(task)


def worker_count(client):
    """How many workers the cluster has now (at least 1, for planning)."""
    return max(1, len(client.scheduler_info().get('workers', {})))


def report_progress(fraction):
    """Called in a task: the fraction of it done (shown in the caller's progress)."""
    try:
        worker = get_worker()
    except ValueError:                 # not on a worker (called directly)
        return
    worker.log_event(PROGRESS_TOPIC, (worker.get_current_task(), fraction))


def run_tasks(client, fn, tasks, on_result, progress=None, weights=None):
    """Run fn(task) for every task on the cluster; on_result(i, result) as each finishes (in the
    order they finish). progress(done, seconds), about once a second, with done the sum of the
    finished tasks' weights and the running ones' weight times their reported fraction.
    A KeyboardInterrupt cancels what has not finished, and is raised again.
    """
    weights = weights or [1.0] * len(tasks)
    run = uuid.uuid4().hex[:8]
    keys = ['geoctl-%s-%d' % (run, i) for i in range(len(tasks))]
    index = {k: i for i, k in enumerate(keys)}
    partial, lock = {}, threading.Lock()

    def on_event(event):
        _, (key, fraction) = event
        if key in index:
            with lock:
                partial[key] = fraction

    client.subscribe_topic(PROGRESS_TOPIC, on_event)
    t0 = time.monotonic()
    futures = [client.submit(checked, fn, task, key=key, pure=False)
               for task, key in zip(tasks, keys)]
    done = 0.0
    finished = as_completed(futures, with_results=False)
    shown = 0.0
    # Ctrl-C sets a flag this loop polls (in the main thread): a KeyboardInterrupt raised inside
    # the client's own waits can be swallowed there (a CI run flew on to 100 % after SIGINT)
    interrupt = threading.Event()
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, lambda *_: interrupt.set()) if main else None
    try:
        while not finished.is_empty():
            if interrupt.is_set():
                raise KeyboardInterrupt
            batch = finished.next_batch(block=False)
            for future in batch:
                i = index[future.key]
                result = future.result()
                future.release()
                with lock:
                    partial.pop(future.key, None)
                done += weights[i]
                on_result(i, result)
            now = time.monotonic()
            if progress and (now - shown >= 1.0 or batch):
                with lock:
                    running = sum(weights[index[k]] * f for k, f in partial.items())
                progress(done + running, now - t0)
                shown = now
            if not batch:
                time.sleep(0.2)
    except KeyboardInterrupt:
        client.cancel([f for f in futures if not f.done()])
        raise
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)
        client.unsubscribe_topic(PROGRESS_TOPIC)
