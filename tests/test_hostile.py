"""The hostile-input corpus (benchmarks/hostile_inputs.py), walked in-process: every API case and every
hostile mesh file must end in a HamsaError subclass, never another exception."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import hamsa

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import hostile_inputs  # noqa: E402

API_CASES = hostile_inputs.api_cases()


@pytest.mark.parametrize("name", list(API_CASES))
def test_every_api_case_raises_a_hamsa_error(name):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning on the way to the error is a defect too
        with pytest.raises(hamsa.HamsaError):
            API_CASES[name]()


def test_every_hostile_mesh_file_raises_a_mesh_error(tmp_path, monkeypatch):
    monkeypatch.setenv("HAMSA_READ_LIMIT", "64M")  # the gzip bomb is refused at 64 MiB instead of 1 GiB
    names = []
    for name, content in hostile_inputs.mesh_files().items():
        (tmp_path / name).write_bytes(content)
        names.append(name)
    names += hostile_inputs.special_files(tmp_path)
    refused = set()
    for name in names:
        try:
            mesh = hamsa.load_mesh(tmp_path / name)
        except hamsa.MeshError:
            refused.add(name)
            continue
        # what loads must still be refused further on: too small for k = 4, or not fit for spectral work
        assert mesh.n_vertices < 5 or name in hostile_inputs.REPAIRABLE, name
    expected = set(names) - set(hostile_inputs.REPAIRABLE) - {"needle.off", "single_triangle.off"}
    assert expected <= refused, sorted(expected - refused)


@pytest.mark.skipif(not os.path.exists("/proc/self/maps"), reason="needs /proc to see where start-up is")
@pytest.mark.parametrize("library", ["_multiarray_umath", "_sparsetools"])
def test_ctrl_c_during_start_up_is_one_line(tmp_path, library):
    """Ctrl-C while the command is still importing numpy's or scipy's compiled modules (not at a fixed
    delay, which a loaded machine would turn into Python's own start-up)."""
    process = subprocess.Popen([sys.executable, "-m", "hamsa", "reproduce", "--quick", "-o", str(tmp_path / "r")],
                               stderr=subprocess.PIPE, text=True)  # fmt: skip
    hostile_inputs.wait_until_mapped(process.pid, library)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    lines = [line for line in stderr.splitlines() if line.strip() and not line.startswith("reproduce:")]
    assert process.returncode == 130 and lines == ["hamsa: interrupted"]
