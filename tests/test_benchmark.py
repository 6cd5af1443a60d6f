"""Dataset-wide matching benchmarks: pairs in parallel, resumable, one table (on the built-in pose family)."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

from hamsa import shapes
from hamsa.cli import main
from hamsa.datasets import load_folder
from hamsa.errors import HamsaError
from hamsa.io import save_mesh
from hamsa.paper.benchmark import benchmark_dataset, evaluate_pair, match_pair

pytest.importorskip("joblib", reason="dataset benchmarks need the [bench] extra")


@pytest.fixture(scope="module")
def pose_dataset(tmp_path_factory):
    """A folder dataset: three poses of the coarse built-in humanoid (identity ground truth)."""
    root = tmp_path_factory.mktemp("poses")
    (root / "meshes").mkdir()
    for i, pose in enumerate(("rest", "walk", "arms up")):
        save_mesh(shapes.humanoid(pose, spacing=0.05), root / "meshes" / f"humanoid{i}.off")
    return root


def test_identity_pair_scores_perfectly():
    mesh = shapes.humanoid(spacing=0.05)
    scored = evaluate_pair(mesh, mesh, np.arange(mesh.n_vertices), k=30, methods=("fmap", "icskm", "sgfe"), points=200)
    assert {(row["method"], row["basis"]) for row in scored["rows"]} == {
        (m, b) for m in ("fmap", "icskm", "sgfe") for b in ("lbo", "hamiltonian")
    }
    for row in scored["rows"]:
        assert row["mean_error"] < 1e-3 and row["within_0.05"] == 1.0, row
    with pytest.raises(HamsaError, match="unknown matching method"):
        match_pair("sift", None, None)


def test_default_potentials_need_no_ground_truth_and_match_the_oracle_on_a_symmetric_body():
    """The built-in humanoid is left-right symmetric, so the LBO's HKS cannot tell left from right; the
    matching potential with signs found from the shapes alone (the default) gives the same Hamiltonian
    basis as the ground truth's signs (``oracle=True``), and with it HKS and SGFE tell the sides apart."""
    rest = shapes.humanoid("rest", spacing=0.05).scaled_to_unit_area()
    walk = shapes.humanoid("walk", spacing=0.05).scaled_to_unit_area()
    truth = np.arange(rest.n_vertices)
    scores = {
        oracle: {
            (r["method"], r["basis"]): r["auc"]
            for r in evaluate_pair(rest, walk, truth, k=40, methods=("hks", "sgfe"), points=300, oracle=oracle)["rows"]
        }
        for oracle in (False, True)
    }
    estimated = scores[False]
    assert estimated["hks", "hamiltonian"] == scores[True]["hks", "hamiltonian"]  # the same signs, the same basis
    assert estimated["hks", "hamiltonian"] > estimated["hks", "lbo"] + 0.2  # measured 0.875 vs 0.538
    assert estimated["sgfe", "hamiltonian"] > estimated["sgfe", "lbo"] + 0.2  # measured 0.977 vs 0.210


def test_dataset_benchmark_runs_in_parallel_resumes_and_tabulates(pose_dataset, tmp_path):
    dataset = load_folder(pose_dataset)
    assert dataset.pairs() == [("humanoid0", "humanoid1"), ("humanoid0", "humanoid2")]
    table = benchmark_dataset(dataset, tmp_path, methods=("hks", "fmap"), k=40, points=300, jobs=2, progress=False)
    assert table["pairs"] == 2 and len(table["rows"]) == 4
    assert table["potentials"] == "estimated (no ground truth)"
    assert (tmp_path / "table.md").read_text().startswith("Hamiltonian potentials: estimated (no ground truth).")
    by = {(r["method"], r["basis"]): r for r in table["rows"]}
    assert by[("hks", "hamiltonian")]["auc"] > by[("hks", "lbo")]["auc"]  # T14 on the pose family
    assert by[("fmap", "hamiltonian")]["within_0.05"] > 0.9  # measured 96% (the LBO fmap flips left and right: 25%)
    pair_files = sorted((tmp_path / "pairs").glob("*.json"))
    stamps = [p.stat().st_mtime_ns for p in pair_files]
    again = benchmark_dataset(dataset, tmp_path, methods=("hks", "fmap"), k=40, points=300, progress=False)
    assert again == table and [p.stat().st_mtime_ns for p in pair_files] == stamps  # nothing recomputed
    (pair_files[0]).write_text("{ truncated")  # a damaged result is recomputed
    benchmark_dataset(dataset, tmp_path, methods=("hks", "fmap"), k=40, points=300, progress=False)
    assert json.loads(pair_files[0].read_text())["rows"]
    assert "\n| dataset | method |" in (tmp_path / "table.md").read_text()


def test_cli_benchmark_matching(pose_dataset, tmp_path, capsys):
    out = tmp_path / "results"
    code = main(["benchmark-matching", str(pose_dataset), "--method", "hks", "-k", "30", "--points", "200",
                 "--limit", "1", "-o", str(out)])  # fmt: skip
    assert code == 0 and "| hks | hamiltonian |" in capsys.readouterr().out
    assert json.loads((out / "table.json").read_text())["pairs"] == 1
    code = main(["benchmark-matching", str(pose_dataset), "--method", "hks", "-k", "30", "--points", "200",
                 "--limit", "1", "--oracle", "--geodesics", "exact", "-o", str(tmp_path / "oracle")])  # fmt: skip
    printed = capsys.readouterr().out
    assert code == 0 and "Hamiltonian potentials: oracle (from the ground truth)." in printed
    assert "Geodesic errors: exact (MMP)." in printed
    heat, exact = (json.loads((folder / "table.json").read_text()) for folder in (out, tmp_path / "oracle"))
    assert heat["geodesics"] == "heat method" and exact["geodesics"] == "exact (MMP)"
    lbo = [[row["mean_error"] for row in table["rows"] if row["basis"] == "lbo"] for table in (heat, exact)]
    assert lbo[0] != lbo[1] and np.allclose(lbo[0], lbo[1], rtol=0.1)  # the same map, measured exactly
    assert main(["benchmark-matching", str(tmp_path / "nowhere"), "-o", str(out)]) == 2
    with pytest.raises(HamsaError, match="geodesics must be one of"):  # before any pair runs
        benchmark_dataset(load_folder(pose_dataset), tmp_path / "bad", methods=("hks",), geodesics="dijkstra")
    assert not (tmp_path / "bad").exists()


def test_a_failing_pair_is_reported_and_the_others_still_run(pose_dataset, tmp_path, capsys):
    root = tmp_path / "data"
    (root / "meshes").mkdir(parents=True)
    for name in ("humanoid0", "humanoid1"):
        (root / "meshes" / f"{name}.off").write_bytes((pose_dataset / "meshes" / f"{name}.off").read_bytes())
    (root / "meshes" / "humanoid2.off").write_text("OFF\n3 1 0\n0 0 0\n")  # truncated file
    out = tmp_path / "results"
    table = benchmark_dataset(load_folder(root), out, methods=("hks",), k=30, points=200, progress=False)
    assert table["pairs"] == 1 and [(f["source"], f["target"]) for f in table["failed"]] == [("humanoid0", "humanoid2")]
    assert "humanoid2" in table["failed"][0]["error"]
    assert sorted(p.name for p in (out / "pairs").glob("*.json")) == ["humanoid0__humanoid1.json"]
    assert "1 pair(s) failed" in (out / "table.md").read_text()
    code = main(["benchmark-matching", str(root), "--method", "hks", "-k", "30", "--points", "200", "-o", str(out)])
    captured = capsys.readouterr()
    assert code != 0 and "1 of 2 pairs failed" in captured.err and "| hks | hamiltonian |" in captured.out


def test_texture_and_landmark_feature_methods_on_a_pose_pair(pose_dataset):
    dataset = load_folder(pose_dataset)
    (source, _), (target, _) = dataset.load("humanoid0"), dataset.load("humanoid1")
    identity = np.arange(source.n_vertices)
    scored = evaluate_pair(source, target, identity, k=40, methods=("hks", "texture", "icskm_geo"), points=300)
    by = {(r["method"], r["basis"]): r for r in scored["rows"]}
    assert by[("texture", "lbo")]["auc"] == by[("hks", "lbo")]["auc"]  # the same matcher on the same LBO bases
    assert by[("texture", "hamiltonian")]["auc"] > by[("texture", "lbo")]["auc"] + 0.05  # the coat tells parts apart
    for basis in ("lbo", "hamiltonian"):
        assert by[("icskm_geo", basis)]["within_0.05"] > 0.9
    with pytest.raises(HamsaError, match="icskm_geo needs the two shapes"):
        match_pair("icskm_geo", None, None, landmarks=([0], [0]))


def test_dataset_benchmark_on_a_dask_cluster_equals_the_local_run(pose_dataset, tmp_path):
    """The pairs run on a Dask cluster given its scheduler address — a scheduler and two worker processes
    talking over TCP on localhost, as a real cluster does — and score exactly as in local worker processes."""
    distributed = pytest.importorskip("distributed", reason="the Dask path needs the [dask] extra")
    dataset = load_folder(pose_dataset)
    local = benchmark_dataset(dataset, tmp_path / "local", methods=("hks",), k=30, points=200, progress=False)
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, protocol="tcp://", host="127.0.0.1", dashboard_address=None
    )
    with cluster as c, distributed.Client(c.scheduler_address) as client:
        assert c.scheduler_address.startswith("tcp://127.0.0.1:")
        assert len(set(client.run(os.getpid).values()) - {os.getpid()}) == 2  # two processes, not this one
        remote = benchmark_dataset(
            dataset,
            tmp_path / "dask",
            methods=("hks",),
            k=30,
            points=200,
            scheduler=c.scheduler_address,
            progress=False,
        )
    assert remote == local and len(list((tmp_path / "dask" / "pairs").glob("*.json"))) == 2


def test_summary_per_class_averages_each_class_and_the_whole():
    from hamsa.paper.benchmark import summarize, table_markdown

    def record(source, auc):
        rows = [{"method": "hks", "basis": b, "auc": auc, "mean_error": 1 - auc, "within_0.05": auc} for b in
                ("lbo", "hamiltonian")]  # fmt: skip
        return {"source": source, "rows": rows}

    records = [record("cat0", 0.2), record("cat0", 0.4), record("dog0", 0.9)]
    table = summarize(records, "TOSCA", {"cat0": "cat", "dog0": "dog"})
    assert [round(r["auc"], 6) for r in table["rows"]] == [0.5, 0.5]  # over pairs, not over classes
    by_class = {(r["class"], r["basis"]): r for r in table["by_class"]}
    assert np.isclose(by_class[("cat", "lbo")]["auc"], 0.3) and by_class[("dog", "hamiltonian")]["pairs"] == 1
    text = table_markdown(table)
    assert text.count("| dataset |") == 1 and text.count("| class |") == 1 and "| dog | hks | lbo | 1 |" in text
    assert "by_class" not in summarize(records[:2], "TOSCA", {"cat0": "cat"})  # one class: no breakdown


def test_landmark_draws_are_pooled_means_of_single_draws(pose_dataset):
    """With every vertex evaluated, two landmark draws score the mean of the two single-draw runs (draw d
    is the single run of seed d), for the landmark method; the other methods do not depend on draws."""
    dataset = load_folder(pose_dataset)
    (source, _), (target, _) = dataset.load("humanoid0"), dataset.load("humanoid2")
    identity = np.arange(source.n_vertices)
    options = dict(k=30, methods=("hks", "icskm"), points=source.n_vertices, landmarks=1)
    single = [evaluate_pair(source, target, identity, seed=seed, **options)["rows"] for seed in (0, 1)]
    pooled = evaluate_pair(source, target, identity, seed=0, draws=2, **options)["rows"]
    for i, row in enumerate(pooled):
        for score in ("auc", "within_0.05", "mean_error"):
            draw_0, draw_1 = single[0][i][score], single[1][i][score]
            expected = (draw_0 + draw_1) / 2 if row["method"] == "icskm" else draw_0
            assert row[score] == pytest.approx(expected, rel=1e-9, abs=1e-12), (row, score)
    with pytest.raises(HamsaError, match="at least one landmark draw"):
        evaluate_pair(source, target, identity, draws=0, **options)


def test_landmark_scale_scales_only_the_landmark_hamiltonian(pose_dataset):
    dataset = load_folder(pose_dataset)
    (source, _), (target, _) = dataset.load("humanoid0"), dataset.load("humanoid2")
    identity = np.arange(source.n_vertices)
    options = dict(k=30, methods=("icskm",), points=300, landmarks=1)
    plain, scaled = (
        evaluate_pair(source, target, identity, landmark_scale=mu, **options)["rows"] for mu in (1.0, 100.0)
    )
    assert plain[0] == scaled[0]  # the LBO row
    assert plain[1]["basis"] == "hamiltonian" and plain[1] != scaled[1]
    with pytest.raises(HamsaError, match="landmark_scale"):
        evaluate_pair(source, target, identity, landmark_scale=0.0, **options)


def test_the_start_map_weights_reach_the_fmap_start_and_are_named_in_the_table(pose_dataset, tmp_path):
    from hamsa.paper.benchmark import load_pair

    dataset = load_folder(pose_dataset)
    table = benchmark_dataset(
        dataset, tmp_path, methods=("fmap",), k=30, points=200, limit=1, progress=False, commutativity_weight=0.0
    )
    assert table["commutativity_weight"] == 0.0
    label = "Descriptor-commutativity weight of the fmap / sgfe start and the ICSKM landmark fit"
    assert f"{label}: 0.0." in (tmp_path / "table.md").read_text()
    expected = evaluate_pair(*load_pair(dataset, "humanoid0", "humanoid1"), k=30, methods=("fmap",), points=200,
                             commutativity_weight=0.0)["rows"]  # fmt: skip
    for row, reference in zip(table["rows"], expected):
        for key in ("auc", "mean_error", "within_0.05"):
            assert row[key] == pytest.approx(reference[key], rel=1e-12)
    hks = benchmark_dataset(dataset, tmp_path / "hks", methods=("hks",), k=30, points=200, limit=1, progress=False)
    assert "commutativity_weight" not in hks and "orientation_weight" not in hks  # no functional-map start
    icskm = benchmark_dataset(dataset, tmp_path / "icskm", methods=("icskm",), k=30, points=200, limit=1,
                              progress=False, commutativity_weight=0.0)  # fmt: skip
    assert icskm["commutativity_weight"] == 0.0 and "orientation_weight" not in icskm  # the landmark fit's
    assert "orientation_weight" not in table  # the default, 0, is no term
    oriented = benchmark_dataset(dataset, tmp_path / "oriented", methods=("fmap",), k=30, points=200, limit=1,
                                 progress=False, commutativity_weight=0.0, orientation_weight=0.1)  # fmt: skip
    assert oriented["orientation_weight"] == 0.1
    assert "Orientation-preserving weight of that start: 0.1." in (tmp_path / "oriented" / "table.md").read_text()
    expected = evaluate_pair(*load_pair(dataset, "humanoid0", "humanoid1"), k=30, methods=("fmap",), points=200,
                             commutativity_weight=0.0, orientation_weight=0.1)["rows"]  # fmt: skip
    assert [row["auc"] for row in oriented["rows"]] == pytest.approx([row["auc"] for row in expected], rel=1e-12)
    for weights, name in (
        ({"commutativity_weight": -1.0}, "commutativity"),
        ({"orientation_weight": -1.0}, "orientation"),
    ):
        with pytest.raises(HamsaError, match=f"{name} weight must be finite"):  # before any pair runs
            benchmark_dataset(dataset, tmp_path / "bad", methods=("fmap",), **weights)
        assert not (tmp_path / "bad").exists()


def test_a_terminated_benchmark_stops_its_worker_processes(pose_dataset, tmp_path):
    """SIGTERM to ``hamsa benchmark-matching --jobs 2`` (a ``kill``, a scheduler's time limit) ends the command
    with 143 and takes its worker processes down with it, instead of leaving them computing."""
    import signal
    import subprocess
    import sys
    import time

    def descendants(pid):
        found, todo = [], [pid]
        while todo:
            try:
                children = Path(f"/proc/{todo.pop()}/task").glob("*/children")
                ids = [int(c) for path in children for c in path.read_text().split()]
            except OSError:
                continue
            found += ids
            todo += ids
        return found

    if not Path("/proc/self/task").exists():
        pytest.skip("needs /proc to list child processes")
    command = [sys.executable, "-m", "hamsa", "benchmark-matching", str(pose_dataset), "--kind", "folder",
               "-k", "60", "--jobs", "2", "-q", "-o", str(tmp_path / "out")]  # fmt: skip
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while len(descendants(process.pid)) < 2 and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)  # until the workers run
    workers = descendants(process.pid)
    assert process.poll() is None and len(workers) >= 2, "the benchmark ended before it could be terminated"
    time.sleep(1.0)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 143 and "terminated" in err
    deadline = time.monotonic() + 30
    while any(Path(f"/proc/{pid}").exists() and "Z" not in _process_state(pid) for pid in workers):
        assert time.monotonic() < deadline, "worker processes still running after the benchmark was terminated"
        time.sleep(0.2)


def _process_state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return "Z"
