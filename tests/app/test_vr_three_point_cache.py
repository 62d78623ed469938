"""benchmarks/vr_three_point.py keys its cache by the model's content: two weights files in one
folder, or one file changed in place, never share a cached result."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.vr_three_point import model_key  # noqa: E402


def test_two_files_in_one_folder_have_their_own_keys(tmp_path):
    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    a.write_bytes(b"weights one")
    b.write_bytes(b"weights two")
    assert model_key(str(a)) != model_key(str(b))
    key = model_key(str(a))
    a.write_bytes(b"weights one, retrained")
    assert model_key(str(a)) != key
    b.write_bytes(b"weights one, retrained")  # the same content under another name: its own readable name
    assert model_key(str(a)).split("-")[-1] == model_key(str(b)).split("-")[-1]


def test_shipped_names_resolve_to_their_files():
    assert model_key("diffusion").startswith("diffusionposer-") and model_key("floor") == "floor"
