"""Sweeps on Ray (``--backend ray``) and resumable results (``--results``, ``--resume``).

One local Ray with 2 CPUs serves the whole module (its start-up takes seconds); the
commands find it connected and use it. Each sweep command must give on Ray exactly the
results of the local process pool (wall-clock timings aside), and a sweep interrupted and
resumed must end with the report of an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import logging
import operator
import os
import shutil
import socket
import subprocess
import sys
from collections.abc import Iterator
from functools import partial
from pathlib import Path
from typing import Any

import pytest
import ray  # the ray extra: installed by `make install` and CI, so never skipped

from tfalda_sim import parallel
from tfalda_sim.cli import main
from tfalda_sim.parallel import (
    IN_FLIGHT_PER_WORKER,
    Backend,
    RayUnavailable,
    check_ray_address,
    ray_stream,
)
from tfalda_sim.sweep_runner import SweepSpec, read_results, run_sweep

TIMING = {"detector_ms_median", "ms_per_frame_median", "ms_per_frame_p95", "times",
          "wall_time_s", "steps_per_s"}
"""Wall-clock figures: they differ between any two runs, whatever the backend."""


@pytest.fixture(scope="module", autouse=True)
def local_ray() -> Iterator[None]:
    """A local Ray with 2 CPUs for the module, shut down after it."""
    ray.init(num_cpus=2, include_dashboard=False, logging_level=logging.ERROR,
             log_to_driver=False)
    yield
    ray.shutdown()


def scrub(obj: Any) -> Any:
    """``obj`` without its wall-clock figures."""
    if isinstance(obj, dict):
        return {k: scrub(v) for k, v in obj.items() if k not in TIMING}
    if isinstance(obj, list):
        return [scrub(v) for v in obj]
    return obj


def records(path: Path) -> list[Any]:
    """A results file's lines (header first), timings scrubbed."""
    return [scrub(json.loads(line)) for line in path.read_text().splitlines()]


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# The backend itself.

def test_ray_stream_gives_results_in_job_order_and_pulls_jobs_lazily() -> None:
    pulled = 0

    def jobs() -> Iterator[int]:
        nonlocal pulled
        for x in itertools.count():
            pulled += 1
            yield x

    results = ray_stream(partial(operator.mul, 3), jobs(), workers=2)
    first = [next(results) for _ in range(7)]
    results.close()
    assert first == [3 * x for x in range(7)]
    assert pulled <= 7 + 2 * IN_FLIGHT_PER_WORKER  # never more than the window ahead
    assert ray.is_initialized()  # a Ray it did not start is left running


def test_a_jobs_error_reaches_the_caller_as_itself() -> None:
    with pytest.raises(ZeroDivisionError):
        list(Backend("ray", 2).stream(partial(operator.truediv, 1), [2, 1, 0, 4]))


@pytest.mark.parametrize("kwargs, message", [
    ({"kind": "dask"}, "backend must be one of"),
    ({"kind": "local", "address": "x:1"}, "needs the ray backend"),
    ({"kind": "local", "workers": None}, "needs a worker count"),
])
def test_backend_refuses_contradictions(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Backend(**kwargs)


# The options.

@pytest.mark.parametrize("argv, message", [
    (["stress", "--ray-address", "127.0.0.1:6379"], "--ray-address names a Ray cluster"),
    (["compare", "--resume"], "--resume continues the sweep saved in --results"),
    (["evaluate-agent", "--results", "r.jsonl", "--resume", "--force"],
     "--force starts afresh"),
    (["evaluate", "--scenario", "straight", "--backend", "ray"],
     "--backend ray only applies to --scenario random"),
    (["evaluate", "--scenario", "random", "--seeds", "0:2", "--results", "r.jsonl",
      "--resume", "--jsonl", "f.jsonl"], "drop --jsonl"),
])
def test_contradictory_sweep_options_are_refused_at_the_parser(
        capsys: pytest.CaptureFixture[str], argv: list[str], message: str) -> None:
    code, _, err = run(capsys, *argv)
    assert code == 2 and "usage:" in err and message in err, err


def test_resume_without_its_file_is_refused(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(capsys, "stress", "--results", str(tmp_path / "r.jsonl"), "--resume",
                       "--out", str(tmp_path / "out"))
    assert code == 2 and "is not a file (nothing to resume)" in err
    assert not (tmp_path / "out").exists()


def test_backend_ray_without_ray_names_the_extra(monkeypatch: pytest.MonkeyPatch,
                                                 tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as if not installed
    code, _, err = run(capsys, "stress", "--backend", "ray", "--seeds", "0:1", "--out",
                       str(tmp_path / "out"))
    assert code == 2 and "pip install 'tfalda-sim[ray]'" in err and "Traceback" not in err


def _in_a_fresh_process(code: str, *argv: str, env: dict[str, str] | None = None
                        ) -> subprocess.CompletedProcess[str]:
    """``code`` in a new Python (no Ray connected there, unlike this module's)."""
    full = {k: v for k, v in os.environ.items() if k not in ("TFALDA_SIM_DEBUG", "RAY_ADDRESS")}
    return subprocess.run([sys.executable, "-c", code, *argv], env=full | (env or {}),
                          capture_output=True, text=True, timeout=300)


def test_a_ray_cluster_that_cannot_be_reached_is_a_clear_error(tmp_path: Path) -> None:
    """Ray starts with the sweep's first job, inside the driver: its failure is still bad
    input (exit 2, one line), not an internal error, and nothing is written."""
    proc = _in_a_fresh_process(
        "import sys; from tfalda_sim.cli import main; sys.exit(main(sys.argv[1:]))",
        "stress", "--backend", "ray", "--ray-address", "bogus::", "--seeds", "0:1",
        "--faults", "none", "--results", str(tmp_path / "r.jsonl"),
        "--out", str(tmp_path / "out"))
    assert proc.returncode == 2, proc.stderr
    assert "error: --ray-address 'bogus::' is not a Ray cluster address" in proc.stderr, (
        proc.stderr)
    assert "internal error" not in proc.stderr and "Traceback" not in proc.stderr
    assert not list(tmp_path.iterdir())  # no report, no results file, no staging left


def _closed_port(host: str = "127.0.0.1") -> int:
    """A local TCP port nothing listens on (bound, then released)."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


@pytest.mark.parametrize("address, reason", [
    ("CLOSED", "nothing listens on port"),
    ("[::1]:CLOSED6", "nothing listens on port"),
    ("127.0.0.1:70000", "port 70000 is out of range"),
    ("127.0.0.1:0", "port 0 is out of range"),
    ("127.0.0.1:" + "9" * 5000, "is out of range"),  # int() of > 4300 digits raises
    ("127.0.0.1:²", "port '²' is not a number"),
    ("head..cluster:6379", "'head..cluster' is not a valid host name"),  # IDNA: empty label
    ("x" * 70 + ".org:6379", "is not a valid host name"),  # a label over 63 characters
])
def test_an_address_that_cannot_be_connected_to_is_named_with_the_reason(
        address: str, reason: str) -> None:
    """ray.init retries such an address for ever (a wrong --ray-address hung a sweep)."""
    if "CLOSED6" in address and not socket.has_ipv6:
        pytest.skip("no IPv6 here")
    address = address.replace("CLOSED6", str(_closed_port("::1"))).replace(
        "CLOSED", f"127.0.0.1:{_closed_port()}")
    with pytest.raises(RayUnavailable) as err:
        check_ray_address(address)
    assert f"could not connect to the Ray cluster at {address}: " in str(err.value)
    assert reason in str(err.value) and "ray start --head" in str(err.value)


@pytest.mark.parametrize("error, reason", [
    (socket.gaierror(-2, "Name or service not known"), "host 'head' is not known"),
    (TimeoutError("timed out"), "head:6379 did not answer within 5 s"),
    (OSError(113, "No route to host"), "No route to host"),
])
@pytest.mark.parametrize("scheme", ["", "ray://"])
def test_a_host_that_is_not_found_or_does_not_answer_is_unreachable(
        error: Exception, reason: str, scheme: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the network: what the connection raises, as one line with the fix for the
    address's form (a Ray Client address has its own port)."""
    def connect(*args: Any, **kwargs: Any) -> None:
        raise error

    monkeypatch.setattr(parallel.socket, "create_connection", connect)
    with pytest.raises(RayUnavailable) as err:
        check_ray_address(f"{scheme}head:6379")
    assert f"at {scheme}head:6379: {reason}; give " in str(err.value)
    assert ("Ray Client server (port 10001" in str(err.value)) == (scheme == "ray://")


@pytest.mark.parametrize("address", ["LISTENING", "[::1]:LISTENING6", "auto", "local"])
def test_an_address_that_answers_or_is_rays_to_read_passes(address: str) -> None:
    """A port that accepts passes; "auto" (this node's cluster) and "local" are left to
    ray.init. Forms that are no address: tests/tfalda_sim/test_ray_address.py."""
    with contextlib.ExitStack() as stack:
        if "LISTENING" in address:
            six = "LISTENING6" in address
            if six and not socket.has_ipv6:
                pytest.skip("no IPv6 here")
            server = stack.enter_context(socket.socket(
                socket.AF_INET6 if six else socket.AF_INET))
            try:
                server.bind(("::1" if six else "127.0.0.1", 0))
            except OSError:
                pytest.skip("no IPv6 loopback here")
            server.listen()
            port = server.getsockname()[1]
            address = f"127.0.0.1:{port}" if not six else f"[::1]:{port}"
        check_ray_address(address)


@pytest.mark.parametrize("command", [["stress", "--faults", "none", "--out", "out"],
                                     ["compare", "--no-thesis", "--out", "out"]])
def test_a_wrong_ray_address_fails_at_once_through_the_console_script(
        command: list[str], tmp_path: Path) -> None:
    """As a user types it: exit 2 and one line naming the address and why, no Ray
    retrying for ever, nothing written."""
    script = shutil.which("tfalda-sim", path=str(Path(sys.executable).parent))
    assert script is not None, "the package is not installed (pip install -e .)"
    address = f"127.0.0.1:{_closed_port()}"
    env = {k: v for k, v in os.environ.items() if k not in ("TFALDA_SIM_DEBUG", "RAY_ADDRESS")}
    proc = subprocess.run([script, *command, "--backend", "ray", "--ray-address", address,
                           "--seeds", "0:1", "--results", "r.jsonl"], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert f"error: could not connect to the Ray cluster at {address}: nothing listens" in (
        proc.stderr), proc.stderr
    assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr
    assert not list(tmp_path.iterdir())


def test_a_local_ray_starts_even_where_ray_address_names_a_cluster() -> None:
    """Without --ray-address the sweep starts its own local Ray with --workers CPUs, even
    if RAY_ADDRESS (or `ray start`) names a cluster: ray.init refuses num_cpus there."""
    proc = _in_a_fresh_process(
        "import ray; from tfalda_sim.parallel import ray_stream; "
        "print(list(ray_stream(abs, [-1, -2, -3], workers=1))); print(ray.is_initialized())",
        env={"RAY_ADDRESS": "127.0.0.1:1"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.split() == ["[1,", "2,", "3]", "False"]  # and shut down after


# Reading a results file back.

def _spec(config: dict[str, Any] | None = None) -> SweepSpec[int]:
    def check(job: int, rec: dict[str, Any]) -> None:
        if rec.get("x") != job:
            raise ValueError(f"it holds job {rec.get('x')}")

    return SweepSpec(command="demo", config=config or {"seeds": "0:5"}, jobs=range(5),
                     total=5, fn=abs, record=lambda j, r: {"x": j}, check=check)


def _file(tmp_path: Path, lines: list[str], tail: str = "") -> Path:
    path = tmp_path / "r.jsonl"
    path.write_text("".join(line + "\n" for line in lines) + tail)
    return path


def test_reading_drops_an_incomplete_last_line_with_a_note(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    head = json.dumps(_spec().header())
    path = _file(tmp_path, [head, '{"x": 0}', '{"x": 1}'], tail='{"x": 2, "ha')
    assert [rec for _, rec in read_results(path, _spec())] == [{"x": 0}, {"x": 1}]
    assert "dropped the incomplete last line 4" in capsys.readouterr().err


@pytest.mark.parametrize("lines, message", [
    (['{"x": 0}'], "does not start with a sweep header"),
    ([], "does not start with a sweep header"),
    (["HEADER-other-command"], "it holds `tfalda-sim other` results"),
    (["HEADER-other-config"], '--seeds was "0:9", now "0:5"'),
])
def test_reading_refuses_another_sweeps_file(tmp_path: Path, lines: list[str],
                                             message: str) -> None:
    from tfalda_sim.cli_common import CliError

    spec = _spec()
    header = {"HEADER-other-command": SweepSpec("other", {"seeds": "0:5"}, (), 5, abs,
                                                spec.record, spec.check).header(),
              "HEADER-other-config": _spec({"seeds": "0:9"}).header()}
    path = _file(tmp_path, [json.dumps(header[x]) if x in header else x for x in lines])
    with pytest.raises(CliError, match="--resume: .*" + message.replace("(", r"\(")):
        list(read_results(path, spec))


def test_resuming_reads_the_journal_and_appends_after_its_last_whole_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A killed sweep's journal (r.jsonl.partial, its last line cut mid-write) is what
    --resume reads; the resumed sweep cuts the broken line and appends the rest there."""
    head = json.dumps(_spec().header())
    journal = tmp_path / "r.jsonl.partial"
    journal.write_text(f'{head}\n{{"x": 0}}\n{{"x": 1}}\n{{"x": 2, "ha')
    (tmp_path / "r.jsonl").write_text(f'{head}\n{{"x": 0}}\n')  # older: not read
    resume = read_results(tmp_path / "r.jsonl", _spec())
    assert resume.path == journal
    seen: list[dict[str, Any]] = []
    end = run_sweep(_spec(), Backend("local", 1), seen.append, results=journal,
                    resume=resume, progress=False)
    assert not end.early and seen == [{"x": x} for x in range(5)]
    assert journal.read_text() == head + "\n" + "".join(f'{{"x": {x}}}\n' for x in range(5))
    err = capsys.readouterr().err
    assert "continuing from" in err and "dropped the incomplete last line 4" in err


def test_a_journal_cut_after_its_header_resumes_on_a_new_line(tmp_path: Path) -> None:
    head = json.dumps(_spec().header())
    journal = tmp_path / "r.jsonl.partial"
    journal.write_text(head)  # the kill came before the header's newline
    resume = read_results(tmp_path / "r.jsonl", _spec())
    run_sweep(_spec(), Backend("local", 1), lambda rec: None, results=journal,
              resume=resume, progress=False)
    assert journal.read_text() == head + "\n" + "".join(f'{{"x": {x}}}\n' for x in range(5))


def test_a_link_at_the_journals_name_is_replaced_not_written_through(tmp_path: Path) -> None:
    precious = tmp_path / "precious.txt"
    precious.write_text("keep me")
    journal = tmp_path / "r.jsonl.partial"
    journal.symlink_to(precious)
    run_sweep(_spec(), Backend("local", 1), lambda rec: None, results=journal,
              progress=False)
    assert precious.read_text() == "keep me" and not journal.is_symlink()
    assert len(journal.read_text().splitlines()) == 6


def test_resuming_a_results_file_copies_it_to_the_journal_first(tmp_path: Path) -> None:
    head = json.dumps(_spec().header())
    results = _file(tmp_path, [head, '{"x": 0}'])
    resume = read_results(results, _spec())
    assert resume.path == tmp_path / "r.jsonl.partial"
    assert resume.path.read_text() == results.read_text()  # the file itself untouched
    assert [rec for _, rec in resume] == [{"x": 0}]


def test_a_damaged_middle_line_is_an_error_naming_it(tmp_path: Path) -> None:
    from tfalda_sim.cli_common import CliError

    path = _file(tmp_path, [json.dumps(_spec().header()), '{"x": 0}', "{oops", '{"x": 2}'])
    with pytest.raises(CliError, match="line 3 is not JSON"):
        list(read_results(path, _spec()))


# Every sweep command: Ray gives the local pool's results; an interrupted sweep resumes.

SWEEPS: dict[str, list[str]] = {
    "evaluate": ["evaluate", "--scenario", "random", "--seeds", "0:3", "--max-frames", "6"],
    "stress": ["stress", "--seeds", "10003:10004", "--faults", "none,blackout"],
    "compare": ["compare", "--no-thesis", "--seeds", "0:3", "--max-frames", "4"],
    "evaluate-agent": ["evaluate-agent", "--seeds", "10003:10005", "--laps", "1",
                       "--speeds", "2.5"],
}

OUT_OPTION = {"stress": ("--out", "out"), "compare": ("--out", "out"),
              "evaluate-agent": ("--out", "out.json"), "evaluate": ("--plot", "seeds.png")}


def _main(*argv: str) -> tuple[int, str, str]:
    """``main(argv)`` with its stdout and stderr (usable outside a test's capsys)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def _sweep(command: str, folder: Path, *extra: str) -> tuple[int, Any, str]:
    folder.mkdir(exist_ok=True)
    opt, name = OUT_OPTION[command]
    code, out, err = _main(*SWEEPS[command], "--results", str(folder / "r.jsonl"), opt,
                           str(folder / name), "--json", *extra)
    return code, (json.loads(out) if out.strip() else None), err


@pytest.fixture(scope="module")
def local_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Any, Path]]:
    """Each sweep on the local pool (2 workers), uninterrupted: the reference."""
    refs = {}
    for command in SWEEPS:
        folder = tmp_path_factory.mktemp(f"local-{command}")
        code, out, err = _sweep(command, folder, "--workers", "2")
        assert code == 0, err
        refs[command] = (out, folder)
    return refs


def _report(command: str, out: Any, folder: Path) -> Any:
    """What a sweep reported and wrote, timings and paths scrubbed."""
    paths = {"results", "out", "plot"}
    report = {k: v for k, v in out.items() if k not in paths}
    if command == "stress":
        report["json"] = json.loads((folder / "out" / "stress.json").read_text())
        report["jsonl"] = (folder / "out" / "stress.jsonl").read_text().splitlines()
    if command == "compare":
        report["json"] = {k: v for k, v in json.loads(
            (folder / "out" / "compare.json").read_text()).items() if k not in paths}
    if command == "evaluate-agent":
        report["json"] = json.loads((folder / "out.json").read_text())
    return scrub(report)


@pytest.mark.parametrize("command", sorted(SWEEPS))
def test_ray_gives_the_local_pools_results(command: str, tmp_path: Path,
                                           local_runs: dict[str, tuple[Any, Path]]
                                           ) -> None:
    ref_out, ref_folder = local_runs[command]
    code, out, err = _sweep(command, tmp_path, "--backend", "ray", "--workers", "2")
    assert code == 0, err
    assert records(tmp_path / "r.jsonl") == records(ref_folder / "r.jsonl")
    assert _report(command, out, tmp_path) == _report(command, ref_out, ref_folder)


@pytest.mark.parametrize("command", sorted(SWEEPS))
def test_an_interrupted_sweep_resumes_to_the_uninterrupted_result(
        command: str, tmp_path: Path, local_runs: dict[str, tuple[Any, Path]],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C after the first result (a KeyboardInterrupt in the second job, in this
    process: --workers 1), then --resume on Ray: the same results file and report."""
    ref_out, ref_folder = local_runs[command]
    target = {"evaluate": "tfalda_sim.evaluation.sweep._one_seed",
              "stress": "tfalda_sim.agents.stress.run_one",
              "compare": "tfalda_sim.evaluation.baseline._one",
              "evaluate-agent": "tfalda_sim.agents.evaluate.drive"}[command]
    module, name = target.rsplit(".", 1)
    real = getattr(sys.modules[module], name)
    calls = 0

    def interrupting(*args: Any, **kwargs: Any) -> Any:
        nonlocal calls
        calls += 1
        if calls == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(target, interrupting)
    code, _, err = _sweep(command, tmp_path, "--workers", "1")
    monkeypatch.setattr(target, real)
    assert code == 130, err
    assert "--resume with the same options continues it" in err.strip().splitlines()[-1]
    kept = (tmp_path / "r.jsonl").read_text().splitlines()
    assert len(kept) == 2  # the header and the first job's result
    code, out, err = _sweep(command, tmp_path, "--resume", "--backend", "ray",
                            "--workers", "2")
    assert code == 0, err
    assert records(tmp_path / "r.jsonl") == records(ref_folder / "r.jsonl")
    assert (tmp_path / "r.jsonl").read_text().splitlines()[:2] == kept  # not redone
    assert _report(command, out, tmp_path) == _report(command, ref_out, ref_folder)


def test_resume_refuses_another_configurations_file(tmp_path: Path,
                                                    local_runs: dict[str, tuple[Any, Path]],
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    _, ref_folder = local_runs["stress"]
    results = tmp_path / "r.jsonl"
    results.write_bytes((ref_folder / "r.jsonl").read_bytes())
    code, _, err = run(capsys, "stress", "--seeds", "10003:10004", "--faults", "none",
                       "--results", str(results), "--resume", "--out", str(tmp_path / "o"))
    assert code == 2 and '--faults was ["none", "blackout"], now ["none"]' in err, err
    code, _, err = run(capsys, "compare", "--no-thesis", "--seeds", "0:3", "--results",
                       str(results), "--resume")
    assert code == 2 and "it holds `tfalda-sim stress` results" in err, err
    assert results.read_bytes() == (ref_folder / "r.jsonl").read_bytes()  # untouched
