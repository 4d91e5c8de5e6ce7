"""``--ray-address``: a form that is no cluster address, and ``auto`` with no Ray running,
each refused in one line of ours that says what to give — never Ray's own advice (about
an ``--address`` flag tfalda-sim does not have) nor its text cut off mid-list.

No Ray is started here (unlike tests/tfalda_sim/test_ray_backend.py): ``auto`` must find
none."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import ray  # the ray extra: installed by `make install` and CI

from tests.cli_helpers import tfalda
from tfalda_sim import parallel
from tfalda_sim.parallel import RayUnavailable, check_ray_address, ray_stream

SWEEP = ("stress", "--backend", "ray", "--seeds", "0:1", "--faults", "none", "--out", "out",
         "--results", "r.jsonl")


def _one_line_of_ours(err: str) -> str:
    lines = err.replace("\r", "\n").strip().splitlines()
    lines = [line for line in lines if not line.startswith("stress:")]  # the progress bar
    assert len(lines) == 1, err
    line = lines[0]
    assert line.startswith("error: ") and "--address" not in line, line
    assert "To fix this" not in line and not line.rstrip().endswith(":"), line
    return line


@pytest.mark.parametrize("address, why", [
    ("http://[::1", "http:// is a web address"),
    ("https://head:8265", "https:// is a web address"),
    ("[::1", "the bracket of the IPv6 host is not closed"),
    ("fe80::1", "an IPv6 host goes in brackets: [fe80::1]:PORT"),
    ("bogus::", "an IPv6 host goes in brackets"),
    ("head", "no port"),
    ("ray://head", "no port"),
    (":6379", "no host"),
    ("[]:6379", "no host"),
    ("[::1]x", "after the IPv6 host's bracket"),
])
def test_an_address_of_no_cluster_form_is_refused_with_the_forms(address: str, why: str,
                                                                 tmp_path: Path) -> None:
    with pytest.raises(RayUnavailable) as err:
        check_ray_address(address)
    message = str(err.value)
    assert message.startswith(f"--ray-address {address!r} is not a Ray cluster address: ")
    assert why in message and "give " in message and "\n" not in message
    run = tfalda(*SWEEP, "--ray-address", address, cwd=tmp_path, code=2)
    assert why in _one_line_of_ours(run.err)
    assert not (tmp_path / "out").exists() and not (tmp_path / "r.jsonl").exists()


def _ray_running_here() -> bool:
    from ray._private.services import find_gcs_addresses

    return bool(find_gcs_addresses())


def test_auto_without_a_cluster_through_the_console_script(tmp_path: Path) -> None:
    if _ray_running_here():  # "auto" would join it: the case is not "no cluster"
        pytest.skip("a Ray runs on this machine (another test run?): auto would join it")
    run = tfalda(*SWEEP, "--ray-address", "auto", cwd=tmp_path, code=2)
    line = _one_line_of_ours(run.err)
    assert "no Ray runs on this machine" in line and "ray start --head" in line, line
    assert "HOST:PORT" in line


def test_auto_without_a_cluster_in_this_process(monkeypatch: pytest.MonkeyPatch) -> None:
    """The same without depending on what runs on the machine: ray.init's own error."""
    def init(*args: Any, **kwargs: Any) -> None:
        raise ConnectionError("Could not find any running Ray instance. Please specify the "
                              "one to connect to by setting `--address` flag or "
                              "`RAY_ADDRESS` environment variable.")

    monkeypatch.setattr(ray, "init", init)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    with pytest.raises(RayUnavailable) as err:
        list(ray_stream(abs, [1], workers=1, address="auto"))
    message = str(err.value)
    assert message.startswith("could not connect to the Ray cluster at auto: no Ray runs")
    assert "--address" not in message and "ray start --head" in message


def test_any_other_refusal_of_ray_init_is_one_line_with_the_fix(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """What Ray says is cut to its first sentence; the fix is ours."""
    def init(*args: Any, **kwargs: Any) -> None:
        raise ValueError("Something Ray did not like: 'x'. To fix this, either:\n  1. a\n  2. b")

    monkeypatch.setattr(ray, "init", init)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(parallel, "check_ray_address", lambda address: None)
    with pytest.raises(RayUnavailable) as err:
        list(ray_stream(abs, [1], workers=1, address="head:6379"))
    message = str(err.value)
    assert message == ("could not connect to the Ray cluster at head:6379: Something Ray did "
                       "not like: 'x'; give the address `ray start --head` printed on the "
                       "head node (HOST:PORT, port 6379 unless it was told otherwise), or "
                       "\"auto\" on a node of the cluster")
