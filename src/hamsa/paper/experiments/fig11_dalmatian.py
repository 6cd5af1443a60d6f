"""Paper §5 (Fig. dalmatian): a texture as the potential (the TOSCA dogs with --data, else humanoid poses).

The dogs come without texture, so we paint one : :func:`hamsa.potentials.dalmatian_texture`
puts seeded black geodesic spots on the first dog, and the ground truth (shared vertex indexing) carries
the same coat to every other dog. The texture potential is ``V = mu x luminance`` (1 on white, 0 in the
spots; mu = 100 on unit-area shapes). For each pair dog0 -> dogN, HKS and WKS nearest-neighbour matching
with the LBO and with the texture Hamiltonian, scored by the Kim et al. protocol (1000 sampled vertices,
symmetries not allowed). Without --data (or with --quick): the built-in humanoid's rest pose against two
other poses. Writes fig11_dalmatian.png (the coat and the mean curves) and fig11_dalmatian.json.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import hamsa
from hamsa import potentials, shapes, viz
from hamsa.datasets import load_tosca
from hamsa.evaluation import TruthDistances, error_curve, sample_points, summary
from hamsa.paper.benchmark import SCORES, TEXTURE_MU, carried_to_target, identity_truth, match_pair
from hamsa.paper.results import BasisScores, PairScores, Scores, TextureResult, from_json, to_json

from ._common import Timer, data_file, kim_curve_panel, parse_args, print_method_scores, save_figure, write_json

MU = TEXTURE_MU
METHODS = ("hks", "wks")


def _pairs(args):
    """(dataset name, [(source name, target name, source, target, truth)])."""
    root = data_file(args.data, "tosca_hires")
    if root and not args.quick:
        dataset = load_tosca(root)
        pairs = []
        for source_name, target_name in dataset.pairs():
            if dataset.classes[source_name] != "dog":
                continue
            (source, source_kept), (target, target_kept) = dataset.load(source_name), dataset.load(target_name)
            truth = identity_truth(source_kept, target_kept, int(max(source_kept.max(), target_kept.max())) + 1)
            pairs.append((source_name, target_name, source.scaled_to_unit_area(), target.scaled_to_unit_area(), truth))
        return "TOSCA dogs", pairs
    spacing = 0.035 if args.quick else 0.02
    poses = list(shapes.HUMANOID_POSES)
    rest = shapes.humanoid(poses[0], spacing).scaled_to_unit_area()
    pairs = [
        (poses[0], pose, rest, shapes.humanoid(pose, spacing).scaled_to_unit_area(), np.arange(rest.n_vertices))
        for pose in poses[1:3]
    ]
    return "built-in humanoid poses", pairs


def run(args) -> TextureResult:
    timer = Timer()
    dataset, pairs = _pairs(args)
    k = 60 if args.quick else 100
    source = pairs[0][2]
    luminance = potentials.from_vertex_colors(source, potentials.dalmatian_texture(source))
    lbo_source = hamsa.eigenbasis(source, k)
    textured_source = hamsa.eigenbasis(source, k, MU * luminance)
    curves = {m: {"lbo": [], "hamiltonian": []} for m in METHODS}
    rows = []
    for source_name, target_name, _, target, truth in pairs:
        known = np.flatnonzero(truth >= 0)
        carried = carried_to_target(luminance, truth, target.n_vertices)  # white where no source vertex maps
        points = known[sample_points(len(known), 1000, 0)]
        distances = TruthDistances(target, truth[points])
        bases = {
            "lbo": (lbo_source, hamsa.eigenbasis(target, k)),
            "hamiltonian": (textured_source, hamsa.eigenbasis(target, k, MU * carried)),
        }
        for method in METHODS:
            for basis, pair in bases.items():
                errors = distances.errors(match_pair(method, *pair)[points])
                named = {"source": source_name, "target": target_name, "method": method, "basis": basis}
                rows.append(from_json(PairScores, {**named, **summary(errors)}))
                curves[method][basis].append(error_curve(errors))
    mean = {m: BasisScores(**{b: _mean_scores(rows, m, b) for b in ("lbo", "hamiltonian")}) for m in METHODS}
    _plot(Path(args.output) / "fig11_dalmatian.png", source, luminance, curves, mean, dataset)
    result = TextureResult(
        dataset=dataset,
        pairs=[(p[0], p[1]) for p in pairs],
        k=k,
        mu=MU,
        spot_area_fraction=float(np.sum(source.face_areas[np.all(luminance[source.faces] < 0.5, axis=1)])),
        methods=mean,
        rows=rows,
        seconds=timer(),
    )
    write_json(Path(args.output) / "fig11_dalmatian.json", result)
    return result


def _mean_scores(rows: list[PairScores], method: str, basis: str) -> Scores:
    """The mean of each score over the pairs of one method and basis."""
    mine = [to_json(r) for r in rows if r.method == method and r.basis == basis]
    return from_json(Scores, {key: float(np.mean([r[key] for r in mine])) for key in SCORES})


def _plot(path, source, luminance, curves, mean, dataset):
    figure, axes = plt.subplots(1, 1 + len(METHODS), figsize=(4.2 * (1 + len(METHODS)), 3.8))
    with tempfile.TemporaryDirectory() as folder:
        try:
            image = viz.render_fields(
                source, [luminance], Path(folder) / "coat.png", titles=["luminance"], cmap="gray", panel_size=(360, 320)
            )
            axes[0].imshow(image)
        except hamsa.MissingDependencyError:  # no [viz] renderer: say so in the panel
            axes[0].text(0.5, 0.5, "install hamsa[viz] to render the coat", ha="center", va="center")
    axes[0].set_axis_off()
    axes[0].set_title(f"synthetic dalmatian coat, V = {MU:g} x luminance", fontsize=10)
    for ax, method in zip(axes[1:], METHODS):
        aucs = {basis: getattr(mean[method], basis).auc for basis in ("lbo", "hamiltonian")}
        labels = {"lbo": "LBO", "hamiltonian": "texture Hamiltonian"}
        kim_curve_panel(ax, curves[method], aucs, f"{method} — {dataset}", labels)
    axes[1].set_ylabel("% correspondences")
    figure.tight_layout()
    save_figure(figure, path)
    plt.close(figure)


if __name__ == "__main__":
    r = run(parse_args(__doc__))
    print_method_scores("fig11", r, "texture Hamiltonian")
    print(f"fig11: {r.seconds} s")
