"""The streaming process pool: results in job order, jobs pulled lazily, workers capped,
deaf to Ctrl-C and dead with their parent."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tfalda_sim import parallel
from tfalda_sim.parallel import IN_FLIGHT_PER_WORKER, resolve_workers, stream


def square(x: int) -> int:
    return x * x


def slow_square(x: int) -> int:
    time.sleep(0.05 * (x % 3))  # finishing out of order in the pool
    return x * x


def fail_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("job 3 failed")
    return x


def ray_imported(_: int) -> bool:
    return "ray" in sys.modules


def test_a_process_that_imported_ray_spawns_its_workers() -> None:
    """Ray's threads outlive ray.shutdown(); a fork copies a lock one of them holds (a
    test-suite run hung so): after `import ray` the workers are spawned (they start
    without it), results as before."""
    pytest.importorskip("ray")
    assert list(stream(ray_imported, range(3), workers=2)) == [False] * 3
    assert list(stream(square, range(5), workers=2)) == [x * x for x in range(5)]


def _children(pid: int) -> set[int]:
    kids: set[int] = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:  # a thread may end between the listing and the read
            text = (task / "children").read_text().split()
        except FileNotFoundError:
            continue
        kids.update(int(t) for t in text)
    return kids


@pytest.mark.parametrize("workers", [1, 2])
def test_results_come_in_job_order(workers: int) -> None:
    assert list(stream(slow_square, range(12), workers=workers)) == [x * x for x in range(12)]


def test_jobs_are_pulled_lazily_from_an_endless_range() -> None:
    pulled = 0

    def jobs() -> Iterator[int]:
        nonlocal pulled
        for x in itertools.count():
            pulled += 1
            yield x

    results = stream(square, jobs(), workers=2)
    first = [next(results) for _ in range(3)]
    results.close()
    assert first == [0, 1, 4]
    # Never more than the window ahead of what was consumed.
    assert pulled <= 3 + 2 * IN_FLIGHT_PER_WORKER
    # A range of 10**8 seeds is never materialised either.
    big = stream(square, range(10**8), workers=2)
    assert next(big) == 0
    big.close()


def test_closing_early_or_an_error_leaves_no_worker_running() -> None:
    me = os.getpid()
    before = _children(me)  # other tests' helpers (a forkserver, …) are not ours
    results = stream(slow_square, range(1000), workers=2)
    next(results)
    workers = _children(me) - before
    assert len(workers) >= 2
    results.close()
    failing = stream(fail_on_three, range(100), workers=2)
    with pytest.raises(ValueError, match="job 3 failed"):
        for _ in failing:
            workers |= _children(me) - before
    deadline = time.monotonic() + 10
    while workers & _children(me) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not workers & _children(me)


def test_workers_are_capped_at_jobs_cpus_and_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(parallel, "available_cpus", lambda: 4)
    monkeypatch.setattr(parallel, "available_memory_bytes", lambda: 100 * 2**30)
    assert resolve_workers(None, None) == (4, None)
    n, why = resolve_workers(100_000, 10)
    assert n == 4 and why is not None and "--workers 100000 capped to 4" in why
    assert "CPU" in why
    assert resolve_workers(3, 1) == (1, "--workers 3 capped to 1: 1 job(s)")
    monkeypatch.setattr(parallel, "available_memory_bytes",
                        lambda: 2 * parallel.WORKER_MEMORY_BYTES)
    n, why = resolve_workers(4, None)
    assert n == 2 and why is not None and "memory" in why
    with pytest.raises(ValueError, match="workers must be ≥ 1"):
        resolve_workers(0, 5)


def test_stress_says_when_it_caps_the_workers(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's reproduction: --workers 100000 for one seed started ~4,900 processes."""
    from tfalda_sim.cli import main

    seen = {}

    def fake_stream(fn: object, jobs: object, *, workers: int) -> Iterator[object]:
        seen["workers"] = workers
        return iter(())

    monkeypatch.setattr("tfalda_sim.parallel.stream", fake_stream)  # what Backend runs
    code = main(["stress", "--seeds", "10000:10001", "--faults", "none", "--workers",
                 "100000", "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err
    assert code == 0 and not (tmp_path / "s").exists()  # no run, nothing written
    assert seen["workers"] <= max(2, parallel.available_cpus())
    assert "--workers 100000 capped to" in err


WORKER_SCRIPT = textwrap.dedent("""
    import sys, time
    from tfalda_sim.parallel import stream

    def nap(x):
        time.sleep(60)
        return x

    if __name__ == "__main__":
        for r in stream(nap, range(100), workers=2):
            pass
""")


def test_workers_ignore_ctrl_c_and_die_with_their_parent(tmp_path: Path) -> None:
    script = tmp_path / "sweep.py"
    script.write_text(WORKER_SCRIPT)
    parent = subprocess.Popen([sys.executable, str(script)], stderr=subprocess.DEVNULL,
                              preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 60
        workers: set[int] = set()
        while time.monotonic() < deadline:
            workers = _children(parent.pid)  # the pool's worker processes
            if len(workers) >= 2:
                break
            time.sleep(0.1)
        assert len(workers) >= 2
        time.sleep(1.0)  # the workers have run their initializer
        for pid in workers:  # Ctrl-C reaches the whole group: the workers ignore it
            os.kill(pid, signal.SIGINT)
        time.sleep(0.5)
        assert all(Path(f"/proc/{pid}").exists() for pid in workers)
        parent.kill()  # SIGKILL: no clean-up code of the parent runs
        parent.wait(10)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(_alive(pid) for pid in workers):
            time.sleep(0.1)
        assert not any(_alive(pid) for pid in workers), "workers outlived their parent"
    finally:
        parent.kill()
        parent.wait(10)


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


def test_a_sweep_stopped_while_a_worker_sends_its_result_exits(tmp_path: Path) -> None:
    """A worker terminated while it writes a result into the pool's result pipe leaves
    half a message there: the pool's manager thread then waited for the rest for ever, and
    the interpreter's exit, which joins that thread, with it (an interrupted `evaluate`
    on a busy host did not exit). Big results make the half-written message likely."""
    script = tmp_path / "stop.py"
    script.write_text(textwrap.dedent("""
        from tfalda_sim.parallel import stream

        def big(job):
            return b"x" * (8 * 2**20)

        if __name__ == "__main__":
            results = stream(big, range(10**9), workers=2)
            for k, _ in enumerate(results):
                if k == 3:
                    break
            results.close()
            print("closed", flush=True)
    """))
    for _ in range(4):  # each hung more often than not
        try:
            proc = subprocess.run([sys.executable, str(script)], capture_output=True,
                                  text=True, timeout=60, check=False)
        except subprocess.TimeoutExpired:
            pytest.fail("the process did not exit within 60 s of closing the stream")
        assert proc.returncode == 0 and proc.stdout == "closed\n", proc.stderr[-2000:]
