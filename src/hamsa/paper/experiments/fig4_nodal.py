"""Fig. 4: nodal domains under two potentials and Courant's theorem (TOSCA dog0 with --data, else the humanoid).

For the LBO and two Hamiltonians (a step potential on one half of the shape, and the normalized
geodesic distance from one extremity, both scaled by lambda_10 of the LBO), the nodal domains of
the 4th-7th eigenfunctions (red/blue by sign, so the nodal lines show as white), and a Courant
check (domains <= last index of the
eigenvalue's cluster) over the first 20 eigenfunctions. Writes fig4_nodal.png and .json.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import hamsa
from hamsa import potentials, viz
from hamsa.geodesic import geodesic_distance
from hamsa.nodal import courant_check, nodal_domains
from hamsa.paper.results import NodalCount, NodalResult

from ._common import Timer, dataset_or_builtin, parse_args, write_json


def run(args) -> NodalResult:
    timer = Timer()
    mesh, name, from_data = dataset_or_builtin(args, "tosca_hires/meshes/dog0.off.gz")
    view = "auto" if from_data else "xz"
    lbo = hamsa.eigenbasis(mesh, 20)
    scale = float(lbo.values[9])
    tip = int(np.argmax(lbo.vectors[:, 1]))
    operators = {
        "LBO": None,
        "step": potentials.step(mesh, lbo.vectors[:, 1] > 0, scale),
        "geodesic": scale * geodesic_distance(mesh, [tip], normalize=True),
    }
    shown = [3, 4, 5, 6]
    fields, titles, counts = [], [], {}
    for label, V in operators.items():
        basis = lbo if V is None else hamsa.eigenbasis(mesh, 20, V)
        rows = courant_check(mesh, basis)
        counts[label] = NodalCount(
            values=basis.values,
            domains=[int(r["domains"]) for r in rows],
            bounds=[int(r["bound"]) for r in rows],
            courant_holds=all(r["holds"] for r in rows),
            violations=[int(r["index"]) for r in rows if not r["holds"]],
        )
        for i in shown:
            count, _ = nodal_domains(mesh, basis.vectors[:, i])
            fields.append(basis.vectors[:, i])  # the nodal lines are the white curves between red and blue
            titles.append(f"{label} #{i + 1}: {count} domains")
    viz.render_fields(
        mesh,
        fields,
        Path(args.output) / "fig4_nodal.png",
        titles=titles,
        cmap="RdBu_r",
        symmetric=True,
        columns=len(shown),
        view=view,
        panel_size=(260, 300),
    )
    result = NodalResult(mesh=name, n_vertices=mesh.n_vertices, scale=scale, operators=counts, seconds=timer())
    write_json(Path(args.output) / "fig4_nodal.json", result)
    return result


if __name__ == "__main__":
    r = run(parse_args(__doc__))
    summary = ", ".join(
        f"{k}: {'holds' if v.courant_holds else 'violated at ' + str(v.violations)}" for k, v in r.operators.items()
    )
    print(f"fig4 ({r.mesh}): Courant over 20 eigenfunctions - {summary} ({r.seconds} s)")
