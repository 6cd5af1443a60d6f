"""Fig. 3: heat diffusion from a point on the head (TOSCA centaur0 with --data, else the built-in humanoid), LBO vs H.

The Hamiltonian's potential is mu times the geodesic distance from the tip of the front-left leg
(Kim et al. landmarks 1 "top of head" and 5 "tip of front left leg"), normalized to [0, 1], with
mu = lambda_20 of the LBO: heat is absorbed where V is large, so under H it survives towards the
leg. With no --data, the built-in humanoid: heat from the top of the head, V = distance from the
sole of the left foot. Temperatures are shown at three times; the JSON holds, per time, the total heat and the
heat centroid's geodesic distance to the leg. Writes fig3_diffusion.png and .json.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import hamsa
from hamsa import viz
from hamsa.diffusion import heat_kernel, total_heat
from hamsa.geodesic import geodesic_distance
from hamsa.paper.results import DiffusionResult, HeatAtTime

from ._common import Timer, builtin_humanoid, data_file, parse_args, write_json


def run(args) -> DiffusionResult:
    timer = Timer()
    path = data_file(args.data, "tosca_hires/meshes/centaur0.off.gz")
    landmarks = data_file(args.data, "tosca_hires/kim_landmarks/centaur.pid")
    if path and landmarks and not args.quick:
        mesh = hamsa.load_mesh(path).scaled_to_unit_area()
        ids = np.loadtxt(landmarks, dtype=np.int64)[:, 0]
        # TOSCA's centaur stands along +z, facing -y: look at its side
        head, leg, name, view = int(ids[1]), int(ids[5]), "TOSCA centaur0", ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    else:
        mesh = builtin_humanoid(args)
        x, z = mesh.vertices[:, 0], mesh.vertices[:, 2]
        head = int(np.argmax(z))  # top of the head
        leg = int(np.argmin(np.where(x > 0, z, np.inf)))  # sole of the left foot
        name, view = "built-in humanoid", "xz"
    k = 100 if args.quick else 200
    lbo = hamsa.eigenbasis(mesh, k)
    mu = float(lbo.values[19])
    distance_to_leg = geodesic_distance(mesh, [leg])  # heat method, computed once
    V = mu * distance_to_leg / distance_to_leg.max()  # = mu * geodesic_distance(mesh, [leg], normalize=True)
    basis = hamsa.eigenbasis(mesh, k, V)
    times = np.array([10.0, 40.0, 160.0]) / lbo.values[-1]  # long enough for k modes to resolve a point source
    fields, titles, rows = [], [], []
    for label, b in (("LBO", lbo), ("Hamiltonian", basis)):
        u = heat_kernel(b, times, [head])[:, :, 0]  # (T, n)
        heat = total_heat(b, u)
        for t, ut, h in zip(times, u, heat):
            fields.append(np.log10(np.maximum(ut, 1e-3 * ut.max())))  # three decades
            titles.append(f"{label} t={t:.2g}")
            weights = np.maximum(ut, 0) * b.mass.diagonal()
            rows.append(
                HeatAtTime(
                    operator=label,
                    t=float(t),
                    total_heat=float(h),
                    mean_distance_to_leg=float(weights @ distance_to_leg / weights.sum()),
                )
            )
    fields.append(V)
    titles.append("potential V")
    viz.render_fields(
        mesh,
        fields,
        Path(args.output) / "fig3_diffusion.png",
        titles=titles,
        cmap="magma",
        columns=4,
        view=view,
        panel_size=(300, 300),
    )
    result = DiffusionResult(
        mesh=name,
        n_vertices=mesh.n_vertices,
        k=k,
        mu=mu,
        source_vertex=head,
        leg_vertex=leg,
        times=times,
        rows=rows,
        seconds=timer(),
    )
    write_json(Path(args.output) / "fig3_diffusion.json", result)
    return result


if __name__ == "__main__":
    r = run(parse_args(__doc__))
    last = [row for row in r.rows if row.t == r.times[-1]]
    print(
        f"fig3 ({r.mesh}): at the last time the heat's mean distance to the leg is "
        f"{last[0].mean_distance_to_leg:.3f} (LBO) vs {last[1].mean_distance_to_leg:.3f} (H) ({r.seconds} s)"
    )
