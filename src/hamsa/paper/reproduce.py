"""``hamsa reproduce``: every experiment of the paper into one self-contained report.

Runs each module of :mod:`hamsa.paper.experiments` into an output folder and writes

- ``index.html``: the figures (embedded, so the page opens offline and can be mailed), the numbers of
  every experiment, and the checklist of the paper's claims (T1–T17) marked reproduced /
  not reproduced / not applicable with the measured value;
- ``results.json``: the same numbers and verdicts, for scripts.

A failing experiment is recorded (with its traceback) and the others still run. Finished experiments are
cached: ``.state/<name>.json`` holds the hash of the inputs (hamsa version, the experiment's source, the
data folder, quick or not) and the SHA-256 of every file the experiment wrote; a re-run skips an
experiment only when both still match, so a run killed midway resumes where it stopped and never trusts
a half-written file (all outputs are written to a temporary file and renamed).
"""

from __future__ import annotations

import base64
import hashlib
import html
import time
import traceback
from pathlib import Path
from types import SimpleNamespace

from hamsa import __version__
from hamsa.cache import code_fingerprint, content_key, load_record, save_record
from hamsa.errors import HamsaError
from hamsa.files import atomic_write
from hamsa.paper.claims import evaluate_claims
from hamsa.paper.experiments import EXPERIMENTS, Experiment
from hamsa.paper.experiments import _common as common
from hamsa.paper.results import ResultFormatError, from_json, to_json


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def input_key(experiment: Experiment, data: str | None, quick: bool) -> str:
    """Hash of everything an experiment's result depends on: hamsa's source (:func:`~hamsa.cache.code_fingerprint`,
    the experiment's module included), the experiment, the data folder, quick."""
    return content_key(code_fingerprint(), experiment.name, [str(Path(data).resolve()) if data else None, bool(quick)])


def _output_files(output: Path, experiment: Experiment) -> list[Path]:
    return sorted(p for p in output.glob(f"{experiment.prefix}*") if p.suffix in (".png", ".json"))


def _cached(experiment: Experiment, output: Path, data: str | None, quick: bool) -> dict | None:
    """The recorded state when its key matches, its numbers read as the experiment's result type and
    every recorded file is intact, else None."""
    state = load_record(output / ".state" / f"{experiment.name}.json", input_key(experiment, data, quick))
    if state is None or state.get("status") != "ok":
        return None
    try:
        from_json(experiment.result_type, state.get("numbers"), experiment.name)
        intact = all(_sha256(output / name) == digest for name, digest in state["files"].items())
    except (OSError, KeyError, TypeError, AttributeError, ResultFormatError):
        return None
    return state if intact else None


def run_experiment(experiment: Experiment, output: Path, data: str | None, quick: bool, force: bool = False) -> dict:
    """Run one experiment unless an intact cached result exists; returns its state record."""
    state_dir = output / ".state"
    state_dir.mkdir(parents=True, exist_ok=True)
    if not force:
        cached = _cached(experiment, output, data, quick)
        if cached is not None:
            return {**cached, "cached": True}
    start = time.perf_counter()
    try:
        result = experiment.module().run(SimpleNamespace(output=str(output), data=data, quick=quick))
        numbers = to_json(result)
        from_json(experiment.result_type, numbers, experiment.name)  # what a cached run will be read as
    except Exception as error:  # recorded in the report; the other experiments still run
        return {
            "name": experiment.name,
            "status": "failed",
            "error": f"{type(error).__name__}: {error}",
            "traceback": traceback.format_exc(),
            "seconds": round(time.perf_counter() - start, 2),
            "cached": False,
        }
    files = {p.name: _sha256(p) for p in _output_files(output, experiment)}
    state = {
        "name": experiment.name,
        "status": "ok",
        "key": input_key(experiment, data, quick),
        "files": files,
        "numbers": numbers,
        "seconds": round(time.perf_counter() - start, 2),
    }
    save_record(state_dir / f"{experiment.name}.json", state)
    return {**state, "cached": False}


def _ok(records: dict, experiment: Experiment) -> bool:
    return experiment.name in records and records[experiment.name]["status"] == "ok"


def _names(name: str, given: str) -> bool:
    """Whether ``given`` names the experiment ``name``: all of it, or its start up to an underscore."""
    return name == given or name.startswith(given.rstrip("_") + "_")


def reproduce(
    output,
    data: str | None = None,
    quick: bool = False,
    force: bool = False,
    only: list[str] | None = None,
    progress: bool = True,
) -> dict:
    """Run the experiments into ``output`` and write ``results.json`` and ``index.html`` there.

    Parameters
    ----------
    output : folder (created)
    data : a folder laid out like shared/data (TOSCA, SCAPE, classic, hand); None: built-in shapes
    quick : smaller sizes (the CI and ``make demo`` setting)
    force : re-run experiments even when their cached results are intact
    only : names of the experiments to run, whole or up to an underscore (``fig1`` is
        ``fig1_harmonics_1d``, not ``fig10_matching``); default all
    progress : show a progress bar over the experiments

    Returns
    -------
    The ``results.json`` content: ``experiments`` (name -> status, seconds, numbers or error, files)
    and ``claims`` (a list of {id, claim, verdict, measured, source}).
    """
    output = Path(output)
    if data is not None and not Path(data).is_dir():
        raise HamsaError(f"data folder '{data}' does not exist")
    chosen = [e for e in EXPERIMENTS if not only or any(_names(e.name, o) for o in only)]
    if not chosen:
        names = ", ".join(e.name for e in EXPERIMENTS)
        raise HamsaError(f"no experiment matches {only}; known: {names}")
    output.mkdir(parents=True, exist_ok=True)
    for stale in [*output.glob(".*.tmp"), *(output / ".state").glob(".*.tmp")]:
        stale.unlink(missing_ok=True)  # left by a killed run; outputs only ever appear by rename
    from tqdm.auto import tqdm

    records = {}
    bar = tqdm(chosen, desc="reproduce", unit="experiment", disable=not progress)
    for experiment in bar:
        bar.set_postfix_str(experiment.name)
        records[experiment.name] = run_experiment(experiment, output, data, quick, force)
        if progress:
            record = records[experiment.name]
            how = "cached" if record["cached"] else f"{record['seconds']} s"
            bar.write(f"  {experiment.name}: {record['status']} ({how})")
    for experiment in EXPERIMENTS:  # with --only, the report still shows the others' intact cached results
        if experiment.name not in records:
            cached = _cached(experiment, output, data, quick)
            if cached is not None:
                records[experiment.name] = {**cached, "cached": True}
    records = {e.name: records[e.name] for e in EXPERIMENTS if e.name in records}
    results = {
        "hamsa_version": __version__,
        "data": str(Path(data).resolve()) if data else None,
        "quick": bool(quick),
        "experiments": {
            name: {k: v for k, v in record.items() if k not in ("key", "traceback")} for name, record in records.items()
        },
        "claims": evaluate_claims(
            {e.name: from_json(e.result_type, records[e.name]["numbers"]) for e in EXPERIMENTS if _ok(records, e)}
        ),
    }
    common.write_json(output / "results.json", results)
    with atomic_write(output / "index.html", "w") as handle:
        handle.write(report_html(results, records, output))
    return results


# ------------------------------------------------------------------------------------ HTML
_STYLE = """
body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #ccc;padding:.25em .6em;
text-align:left;vertical-align:top;font-size:.9em}th{background:#f3f3f3}img{max-width:100%;border:1px solid #ddd}
caption{text-align:left;font-weight:bold;padding:.2em 0}
.reproduced{background:#e3f6e3}.not-reproduced{background:#fde2e2}.not-applicable,.not-run{background:#eee}
pre{background:#f7f7f7;padding:.5em;overflow:auto;font-size:.8em}code{font-size:.9em}
"""


def _is_scalar(value) -> bool:
    return isinstance(value, (int, float, bool, str)) or value is None


def _records(value, label: str = "") -> list[tuple[str, dict]] | None:
    """A dict nesting down to dicts of scalars with the same keys, or a list of such dicts, as labelled rows
    ("hks · lbo", {"auc": ...}); None when it is not that shape."""
    if isinstance(value, list):
        rows = [(f"{label}{i}", v) for i, v in enumerate(value)]
    elif isinstance(value, dict) and value and all(_is_scalar(v) for v in value.values()):
        return [(label.removesuffix(" · "), value)] if label else None
    elif isinstance(value, dict) and value:
        rows = []
        for key, inner in value.items():
            found = _records(inner, f"{label}{key} · ")
            if found is None:
                return None
            rows += found
    else:
        return None
    if not rows or not all(isinstance(r, dict) and r and all(map(_is_scalar, r.values())) for _, r in rows):
        return None
    return rows if len({tuple(r) for _, r in rows}) == 1 else None


def _tables(numbers: dict) -> list[tuple[str, list[str], list[list[str]]]]:
    """The numbers as labelled tables: (caption, header, rows). Scalars and short lists go in one
    quantity / value table; a nesting of records (methods x bases x scores, per-pair rows) gets a table of
    its own with one column per score."""
    plain, tables = [], []

    def walk(value, name):
        rows = None if isinstance(value, list) and all(map(_is_scalar, value)) else _records(value)
        if rows is not None:
            header = list(rows[0][1])
            labelled = isinstance(value, dict)  # list rows carry their own labels (source, method, ...)
            cells = [([label] if labelled else []) + [_format(r[h]) for h in header] for label, r in rows]
            tables.append((name, ["", *header] if labelled else header, cells))
        elif isinstance(value, dict):
            for key, inner in value.items():
                walk(inner, f"{name}.{key}" if name else key)
        elif isinstance(value, list):
            if len(value) <= 8 and all(map(_is_scalar, value)):
                plain.append([name, ", ".join(_format(v) for v in value)])
        else:
            plain.append([name, _format(value)])

    walk(numbers or {}, "")
    return [("", ["quantity", "value"], plain), *tables] if plain else tables


def _data_used(numbers: dict) -> str | None:
    """The shapes an experiment ran on, from its numbers (its caption describes the data it can use)."""
    for key in ("mesh", "dataset"):
        if isinstance((numbers or {}).get(key), str):
            return numbers[key]
    meshes = sorted({r["mesh"] for r in (numbers or {}).get("rows", []) if isinstance(r, dict) and "mesh" in r})
    return ", ".join(meshes) or None


def _format(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def report_html(results: dict, records: dict, output: Path) -> str:
    """The self-contained report page (figures embedded as base64 PNG)."""
    e = html.escape
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>hamsa reproduce</title>",
        f"<style>{_STYLE}</style></head><body>",
        "<h1>Hamiltonian Operator for Spectral Shape Analysis — reproduced by hamsa</h1>",
        f"<p>hamsa {e(results['hamsa_version'])}; data: {e(str(results['data'] or 'built-in shapes'))}; "
        f"{'quick sizes' if results['quick'] else 'full sizes'}. Paper: Choukroun, Shtern, Bronstein &amp; "
        "Kimmel, IEEE TVCG 2018. Numbers are also in <code>results.json</code>.</p>",
    ]
    verdicts = [c["verdict"] for c in results["claims"]]
    failed = [n for n, r in records.items() if r["status"] != "ok"]
    parts.append(
        f"<p><b>{verdicts.count('reproduced')} of {len(verdicts)} claims reproduced</b>, "
        f"{verdicts.count('not reproduced')} not reproduced"
        + (f"; <b>failed experiments: {e(', '.join(failed))}</b>" if failed else "")
        + ". Experiments: "
        + ", ".join(f"<a href='#{x.name}'>{e(x.name)}</a>" for x in EXPERIMENTS if x.name in records)
        + "</p>"
    )
    parts.append(
        "<h2>Claims checklist</h2><table><tr><th>id</th><th>claim</th><th>verdict</th><th>measured</th>"
        "<th>source</th></tr>"
    )
    for claim in results["claims"]:
        css = claim["verdict"].replace(" ", "-")
        parts.append(
            f"<tr class='{css}'><td>{e(claim['id'])}</td><td>{e(claim['claim'])}</td><td>{e(claim['verdict'])}</td>"
            f"<td>{e(claim['measured'])}</td><td>{e(claim['source'])}</td></tr>"
        )
    parts.append("</table>")
    for experiment in EXPERIMENTS:
        record = records.get(experiment.name)
        if record is None:
            continue
        parts.append(f"<h2 id='{experiment.name}'>{e(experiment.title)}</h2>")
        doc = (experiment.module().__doc__ or "").strip()
        parts.append(f"<p>{e(doc)}</p>".replace("\n\n", "</p><p>"))
        if record["status"] != "ok":
            parts.append(f"<p><b>Failed</b>: {e(record['error'])}</p><pre>{e(record.get('traceback', ''))}</pre>")
            continue
        for name in record["files"]:
            if name.endswith(".png"):
                encoded = base64.b64encode((output / name).read_bytes()).decode()
                parts.append(f"<p><img alt='{e(name)}' src='data:image/png;base64,{encoded}'></p>")
        used = _data_used(record["numbers"])
        parts.append(f"<p>{f'<b>Data in this run:</b> {e(used)}. ' if used else ''}"
                     f"{record['seconds']} s{' (cached)' if record['cached'] else ''}</p>")  # fmt: skip
        for caption, header, rows in _tables(record["numbers"]):
            parts.append(f"<table>{f'<caption>{e(caption)}</caption>' if caption else ''}<tr>")
            parts += [f"<th>{e(h)}</th>" for h in header] + ["</tr>"]
            parts += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in rows]
            parts.append("</table>")
    parts.append("</body></html>")
    return "\n".join(parts)
