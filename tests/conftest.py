"""Shared test fixtures: where the real data lies, and a skip when it is not there."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


# "The same answer" from two float32 code paths of one computation (batched and single matmuls,
# a traced graph and eager modules, the lean decoder and nn.TransformerDecoder): they sum in
# other orders, so each output is a few ulps (eps 1.2e-7) apart, more after several layers and
# steps, and how many depends on the machine's SIMD width. A relative 1e-4 (~800 ulps) bounds it
# at any magnitude; the absolute 1e-5 covers values that pass near zero.
F32_PATHS = {"rtol": 1e-4, "atol": 1e-5}


def data_root() -> Path:
    return Path(os.environ.get("IMUCAP_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    root = data_root()
    if not (root / "hdm05").is_dir() or not (root / "bandai").is_dir():
        pytest.skip(f"real motion data not found at {root} (set IMUCAP_DATA)")
    return root


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """The suite runs two xdist workers on two cores: one intra-op thread each (oversubscribed
    OpenMP threads crawl). Set before every test, it also undoes a CLI test's --threads."""
    torch = sys.modules.get("torch")  # only if the test already uses it: driver tests need no torch
    if torch is not None:
        torch.set_num_threads(1)
    yield


# scripts/test.sh runs the realtime modules (nice 0) and the rest (nice 10, two workers) at the same
# time, so the CPU-bound tests take only the cores the real-time ones leave, then the solo modules alone.
#
# Tests that need the machine to keep up in real time (simulated devices streaming through the
# drivers and the hub, the live demo, a window): one at a time, above the rest. At the same
# priority as CPU-bound tests, a suit test lost a device's samples for whole seconds.
REALTIME_MODULES = {"sim_devices/test_suit.py", "drivers/test_batched.py",
                    "drivers/test_end_to_end.py",
                    "app/gui/test_main_window.py", "app/cli/test_demo.py", "app/capture/test_identify.py",
                    "app/cli/test_setup.py", "app/capture/test_capture_e2e.py",
                    "app/capture/test_capture_loopback.py",
                    "app/gui/test_window_unplug.py", "app/gui/test_window_workflow.py",
                    "app/gui/test_window_simulate.py",
                    "app/cli/test_bench_latency.py", "sim_devices/test_xsens_can_twin.py",
                    "drivers/xsens_can/test_shared_bus.py", "app/gui/test_outdoor_view.py", "app/streams/test_cli.py",
                    "sim_devices/test_wireless_twins.py", "test_lean_install.py", "app/capture/test_simulate_vr.py",
                    "drivers/test_ximu3_loss.py", "drivers/test_ximu3_tcp.py",
                    "drivers/test_hub_readers.py"}
# The realtime modules run in two lanes side by side, one test at a time in each: they mostly wait on the
# clock (one lane took 7:58 for ~1:30 of CPU), and one lane after the other was the suite's critical path.
# The windows (software GL under Xvfb) and the lean install in one lane, the demos, the bench and the devices
# in the other: ~4 minutes each (docs/testing.md).
WINDOW_MODULES = {"app/gui/test_main_window.py", "app/gui/test_window_unplug.py", "app/gui/test_window_workflow.py",
                  "app/gui/test_window_simulate.py", "app/gui/test_outdoor_view.py", "test_lean_install.py",
                  "drivers/test_ximu3_loss.py"}
assert WINDOW_MODULES <= REALTIME_MODULES


# Separate processes in real time (a simulator, `imucap capture`) whose figures (a calibration
# from integrated accelerations, poses per second) depend on the cores: with another CPU-bound
# test at the same priority the capture's walk calibration put a CAN wrist 10-20 deg off. One at a
# time, in a run of their own after the realtime one, beside the niced rest (scripts/test.sh). Their
# own replays and evaluates run niced (tests/app/capture/live_capture.py).
SOLO_MODULES = {"app/capture/test_capture_e2e.py", "test_readme.py", "app/capture/test_replay_reproduces_capture.py",
                "app/capture/test_capture_wireless.py", "app/capture/test_capture_vr.py"}
# ... in two lanes once both realtime lanes are done, one capture at a time in each: two captures at once ask
# for ~1 of the 2 cores with the live step at ~6 ms (the lanes 2:36-2:42 / 3:17-3:31; docs/testing.md)
SOLO_SECOND = {"app/capture/test_capture_vr.py", "app/capture/test_capture_wireless.py", "test_readme.py"}
assert SOLO_SECOND <= SOLO_MODULES


# Real-data tests that only read files, in one process on one core, like any unit test: spread
# over both workers per test. The other real-data modules (loading or training on the whole
# dataset) keep each module on one worker, so its module fixtures are built once.
DATA_ONE_CORE_MODULES = {"inference/loaders/test_real_data.py", "inference/loaders/test_cmu.py"}


# scripts/test.sh names each run's share (``IMUCAP_TEST_RUN``: realtime, windows, solo, solo2 or rest) so that its
# workers import only the modules they will run: every worker collected all ~1,400 tests (torch,
# Qt and the model's modules each time) to deselect most of them by marker
_RUN_MODULES = {"realtime": REALTIME_MODULES - WINDOW_MODULES, "windows": WINDOW_MODULES,
                "solo": SOLO_MODULES - SOLO_SECOND, "solo2": SOLO_SECOND}
# a module renamed or removed without its entry here would move its tests to another run unnoticed
_MISSING = sorted(m for m in REALTIME_MODULES | SOLO_MODULES if not (REPO / "tests" / m).is_file())
assert not _MISSING, f"tests/conftest.py names test modules that do not exist: {_MISSING}"


def pytest_ignore_collect(collection_path, config):
    run = os.environ.get("IMUCAP_TEST_RUN")
    if run is None or collection_path.suffix != ".py" or not collection_path.name.startswith("test_"):
        return None
    try:
        module = collection_path.relative_to(REPO / "tests").as_posix()
    except ValueError:
        return None
    if run in _RUN_MODULES:
        return True if module not in _RUN_MODULES[run] else None
    if run == "rest":
        return True if module in REALTIME_MODULES or module in SOLO_MODULES else None
    return None


def pytest_collection_modifyitems(config, items):
    for item in items:
        module = item.path.relative_to(REPO / "tests").as_posix()
        if module in SOLO_MODULES:
            item.add_marker(pytest.mark.solo)
        elif module in REALTIME_MODULES:
            item.add_marker(pytest.mark.realtime)
        elif item.get_closest_marker("data") is not None and module not in DATA_ONE_CORE_MODULES:
            item.add_marker(pytest.mark.xdist_group(module))  # its module fixtures built once
    if getattr(config.option, "loadgroup", False):  # an xdist worker under --dist loadgroup
        _name_groups(items)


def _name_groups(items) -> None:
    """Put each test's xdist_group into its node id (``nodeid@group``), which is what
    ``--dist loadgroup`` schedules by. xdist 3.8 writes it to ``item._nodeid``, which pytest 9
    no longer reads (a node's id is ``item._id``): without this every group was silently
    spread over both workers, and a module's expensive fixtures were built on each
    (docs/testing.md)."""
    try:
        from _pytest.nodeid import coerce_node_id
    except ImportError:  # a pytest that still reads _nodeid: xdist's own hook does it
        return
    for item in items:
        names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                        for m in item.iter_markers("xdist_group")})
        suffix = "@" + "_".join(names)
        if names and not item.nodeid.endswith(suffix):
            item._id = coerce_node_id(item.nodeid + suffix)
