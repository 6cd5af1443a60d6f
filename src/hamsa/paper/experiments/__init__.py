"""The paper's experiments, one module per figure; ``hamsa reproduce`` runs them all into one report.

Every module has ``run(args) -> <Result>``: ``args`` has ``output`` (a folder), ``data`` (a folder laid out
like shared/data, or None for built-in shapes) and ``quick`` (smaller sizes). It writes ``<name>.json`` and one
or more PNGs whose names start with its figure prefix (``fig7_...``) into ``output``, and returns its numbers
as the frozen dataclass its ``run`` is annotated with (:mod:`hamsa.paper.results`).
Each module also runs on its own: ``python -m hamsa.paper.experiments.fig2_step_potential -o report/``.
"""

from __future__ import annotations

import importlib
import typing
from dataclasses import dataclass


@dataclass(frozen=True)
class Experiment:
    """One entry of the report: the module ``hamsa.paper.experiments.<name>`` and what it shows."""

    name: str
    title: str

    @property
    def prefix(self) -> str:
        """The start of every file the experiment writes (``fig7_`` for ``fig7_optimize_hand``)."""
        return self.name.split("_", 1)[0] + "_"

    def module(self):
        return importlib.import_module(f"{__name__}.{self.name}")

    @property
    def result_type(self) -> type:
        """The result dataclass the experiment's ``run`` returns (its return annotation)."""
        return typing.get_type_hints(self.module().run)["return"]


EXPERIMENTS = (
    Experiment("fig1_harmonics_1d", "Fig. 1 — harmonics on an interval under three potentials"),
    Experiment("fig2_step_potential", "Fig. 2 — a finite step potential traps the low modes"),
    Experiment("fig3_diffusion", "Fig. 3 — Hamiltonian heat diffusion avoids high potential"),
    Experiment("fig4_nodal", "Fig. 4 — nodal domains and Courant's theorem"),
    Experiment("fig5_noise", "Fig. 5 — robustness to geometric, potential and topological noise"),
    Experiment("fig6_optimize_1d", "Fig. 6 — the optimal potential for a linear function on an interval"),
    Experiment("fig7_optimize_hand", "Fig. 7 — an optimized potential represents a hand's coordinates"),
    Experiment("fig8_compression", "Fig. 8 — spectral mesh compression, rate vs distortion"),
    Experiment("fig9_cmm", "Fig. 9 — compressed manifold modes: IRLS vs ADMM"),
    Experiment("fig10_matching", "Fig. 10 — shape matching: Kim et al. curves, LBO vs Hamiltonian, oracle potentials"),
    Experiment("fig11_dalmatian", "Fig. dalmatian — a texture potential for matching the TOSCA dogs"),
    Experiment("claims_checks", "Numerical checks of the paper's theorems (T1–T5, T8, T13, T15)"),
)
