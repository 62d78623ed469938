"""The core install without its extras (pyproject.toml): capture of simulated serial devices,
replay and export to BVH, CSV and .mot run in processes where Dask, pyarrow, bleak, ximu3, ezc3d
and c3d cannot be imported; a command that needs one says which extra to install, in one line.

The packages are hidden by a ``sitecustomize`` on PYTHONPATH that puts a finder first on
``sys.meta_path`` refusing them, in every Python process the commands start (the devices'
simulator too)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from drivers.extras import EXTRAS

pytestmark = [pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def lean_env(tmp_path_factory) -> dict[str, str]:
    site = tmp_path_factory.mktemp("lean_site")
    (site / "sitecustomize.py").write_text(textwrap.dedent(f"""
        import sys

        HIDDEN = {sorted(EXTRAS)!r}

        class _NotInstalled:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in HIDDEN:
                    raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
                return None

        sys.meta_path.insert(0, _NotInstalled())
    """))
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}


def imucap(env, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "app.cli.main", *args], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=ROOT)


def test_the_hiding_works(lean_env):
    for name in EXTRAS:
        res = subprocess.run([sys.executable, "-c", f"import {name}"], capture_output=True, text=True, env=lean_env)
        assert res.returncode != 0 and "ModuleNotFoundError" in res.stderr, name


def test_capture_replay_and_export_run_without_the_extras(lean_env, tmp_path):
    rec = tmp_path / "walk.h5"
    res = imucap(lean_env, "demo", "--headless", "--seconds", "6", "--json", "--protocol", "xbus",
                 "--sensors", "pelvis,l_shank,r_shank", "--record", str(rec), timeout=400)
    assert res.returncode == 0, res.stderr[-3000:]
    assert json.loads(res.stdout.strip().splitlines()[-1])["frames"] > 0 and rec.is_file()
    res = imucap(lean_env, "replay", str(rec), "--json")
    assert res.returncode == 0, res.stderr[-3000:]
    outs = [tmp_path / "walk.bvh", tmp_path / "walk.csv", tmp_path / "walk.mot"]
    res = imucap(lean_env, "export", str(rec), *[a for o in outs for a in ("--out", str(o))])
    assert res.returncode == 0, res.stderr[-3000:]
    assert all(o.is_file() and o.stat().st_size > 0 for o in outs)


@pytest.mark.parametrize("args, extra", [
    (("batch", "{rec}", "--out", "{tmp}/b"), "batch"),
    (("export", "{rec}", "--out", "{tmp}/walk.c3d"), "gaitlab"),
    (("devices", "probe", "ximu3://udp/45999", "--seconds", "0.5", "--json"), "ximu3"),
    (("devices", "probe", "movella-dot://D4:22:CD:00:01:27", "--seconds", "0.5", "--json"), "ble"),
])
def test_a_missing_extra_is_one_line_naming_it(lean_env, tmp_path, args, extra):
    from app.capture.offline_session import write_session

    rec = tmp_path / "rec.h5"
    write_session(rec, seconds=1.0, seed=1)
    res = imucap(lean_env, *[a.format(rec=rec, tmp=tmp_path) for a in args], timeout=120)
    assert res.returncode == 2, res.stderr[-2000:]
    assert res.stderr.strip().count("\n") == 0 and "Traceback" not in res.stderr, res.stderr
    assert f"pip install 'imucap[{extra}]'" in res.stderr
