"""The sweep's results as text: a Markdown report laid out like the paper's Table 1, and the same
table as rows for a Prefect table artifact. Pure functions of :func:`~.stats.sweep_stats`'s
dict (and the run rows, for failures and cost).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from sim2radar.experiment.profiles import BASELINE
from sim2radar.experiment.stats import as_rows

__all__ = ["condition_label", "results_markdown", "results_table_rows"]

_LABELS = {
    BASELINE: "Baseline",
    "sim-pretrain": "Sim Pretrain",
    "sim-gt-pretrain": "Sim-GT Pretrain",
    "sim-one-material-pretrain": "Sim One-Material Pretrain",
}
_DASH = "—"


def condition_label(condition: str) -> str:
    """Table heading of a condition (``sim-pretrain`` -> ``Sim Pretrain``)."""
    return _LABELS.get(condition, condition)


def _f(v: float | None, digits: int = 1, signed: bool = False) -> str:
    if v is None:
        return _DASH
    return f"{v:+.{digits}f}" if signed else f"{v:.{digits}f}"


def _p(v: float | None) -> str:
    if v is None:
        return _DASH
    return "<0.001" if v < 0.001 else f"{v:.3f}"


def _ratio(r: float | None) -> str:
    """Sim:Real as in Table 1: ``15:1``, ``7.3:1``, ``0.7:1``."""
    if r is None:
        return _DASH
    return f"{r:.0f}:1" if r >= 10 else f"{r:.1f}:1"


def _pct(fraction: float) -> str:
    return f"{100 * fraction:g} %"


def _mean_std(cell: Mapping[str, Any] | None) -> str:
    if cell is None or cell["mean"] is None:
        return _DASH
    if cell["std"] is None:
        return f"{cell['mean']:.1f}"
    return f"{cell['mean']:.1f} ± {cell['std']:.1f}"


def _cells(stats: Mapping[str, Any]) -> dict[tuple[str, float], Mapping[str, Any]]:
    return {(c["condition"], float(c["fraction"])): c for c in stats["cells"]}


def results_table_rows(stats: Mapping[str, Any]) -> list[dict[str, str]]:
    """Table 1 as rows of strings, one per (non-baseline condition, fraction), for a Prefect
    table artifact (``create_table_artifact(table=rows)``).

    Keys: ``condition``, ``real data``, ``N``, ``Sim:Real``, ``baseline``, ``condition AP``,
    ``Δ``, ``95 % CI`` (Student t), ``p (Holm)``, ``d_z``, ``k/n``, ``verdict``,
    ``bootstrap CI`` (reference only: anti-conservative at 5 pairs). APs as ``mean ± std``
    (sample std over trials), Δ = condition minus baseline.
    """
    cells = _cells(stats)
    level = f"{100 * (1 - float(stats['alpha'])):g} % CI"
    rows = []
    for comp in stats["comparisons"]:
        f = float(comp["fraction"])
        base = cells.get((BASELINE, f))
        cond = cells.get((comp["condition"], f))
        n_real = next((c["n_real_frames"] for c in (base, cond)
                       if c is not None and c["n_real_frames"] is not None), None)
        lo, hi = comp["t_ci"]
        b_lo, b_hi = comp["bootstrap_ci"]
        rows.append({
            "condition": comp["condition"],
            "real data": _pct(f),
            "N": _DASH if n_real is None else str(n_real),
            "Sim:Real": _ratio(cond["sim_real_ratio"] if cond else None),
            "baseline": _mean_std(base),
            "condition AP": _mean_std(cond),
            "Δ": _f(comp["mean_diff"], signed=True),
            level: _DASH if lo is None else f"[{_f(lo, signed=True)}, {_f(hi, signed=True)}]",
            "p (Holm)": _p(comp["p_holm"]),
            "d_z": _f(comp["d_z"], 2),
            "k/n": f"{comp['k_improved']}/{comp['n_pairs']}",
            "verdict": comp["verdict"],
            "bootstrap CI": _DASH if b_lo is None
            else f"[{_f(b_lo, signed=True)}, {_f(b_hi, signed=True)}]",
        })
    return rows


def _table(header: list[str], rows: list[list[str]], align: list[str]) -> list[str]:
    out = ["| " + " | ".join(header) + " |",
           "|" + "|".join("---:" if a == "r" else ":---" for a in align) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def results_markdown(
    stats: Mapping[str, Any],
    runs: Iterable[Mapping[str, Any]] | Any = (),
    *,
    title: str,
    real_domain_label: str,
    proxy: bool | None = None,
) -> str:
    """A Markdown report of a sweep.

    Parameters
    ----------
    stats : :func:`~sim2radar.experiment.stats.sweep_stats` output.
    runs : the ``experiment_runs`` rows (list of dicts or a pyarrow Table), for the failed runs'
        errors and the sweep's cost; may be empty.
    title : the report's heading.
    real_domain_label : what the "real" data is, e.g. ``"proxy-real (reference radar
        simulation)"`` or ``"IFR (measured)"``.
    proxy : whether the real domain is a stand-in for measured radar (default: the label
        starts with ``proxy``). A proxy report says so at the top and at the end.

    Returns
    -------
    str — Table 1 (one block per non-baseline condition), every trial's value per cell, failed
    runs, notes, and the real domain's status.
    """
    if proxy is None:
        proxy = real_domain_label.strip().lower().startswith("proxy")
    domain_line = (
        f"**real = {real_domain_label}**: a stand-in for measured radar. These results are not "
        "claims about measured radar." if proxy else
        f"real = {real_domain_label} (measured radar)."
    )
    cells = _cells(stats)
    alpha = float(stats["alpha"])
    level = f"{100 * (1 - alpha):g} % CI"
    out = [f"# {title}", "", domain_line, "",
           f"Metric: `{stats['metric']}` (AP in %), mean ± std over trials; Δ = condition "
           f"minus baseline, paired by trial, with its {level} (Student t); p Holm-adjusted "
           f"across fractions; verdict at alpha = {alpha:g}.", ""]

    rows_by_cond: dict[str, list[dict[str, str]]] = {}
    for row in results_table_rows(stats):
        rows_by_cond.setdefault(row["condition"], []).append(row)
    for cond, rows in rows_by_cond.items():
        label = condition_label(cond)
        out += [f"## {label} vs {condition_label(BASELINE)}", ""]
        header = ["Real Data", "N", "Sim:Real", condition_label(BASELINE), label,
                  f"Δ [{level}]", "p (Holm)", "d_z", "k/n", "Verdict", "Bootstrap CI (ref.)"]
        body = [[r["real data"], r["N"], r["Sim:Real"], r["baseline"], r["condition AP"],
                 f"{r['Δ']} {r[level]}" if r[level] != _DASH else r["Δ"], r["p (Holm)"],
                 r["d_z"], r["k/n"], r["verdict"], r["bootstrap CI"]] for r in rows]
        out += _table(header, body, ["r", "r", "r", "r", "r", "l", "r", "r", "r", "l", "l"])
        out.append("")

    trials = sorted({t for c in stats["cells"] for t in c["trials"]})
    out += ["## Every trial", ""]
    header = ["Condition", "Real Data", *(f"trial {t}" for t in trials), "mean ± std", "failed"]
    body = []
    for cond in stats["conditions"]:
        for f in stats["fractions"]:
            cell = cells.get((cond, float(f)))
            if cell is None:
                continue
            by_trial = dict(zip(cell["trials"], cell["values"], strict=True))
            body.append([condition_label(cond), _pct(float(f)),
                         *(_f(by_trial.get(t)) for t in trials), _mean_std(cell),
                         str(cell["n_failed"])])
    out += _table(header, body, ["l", "r", *("r" for _ in trials), "r", "r"]) + [""]

    rows = as_rows(runs)
    failed = [r for r in rows if r.get("status") == "failed"]
    if rows:
        n_status = {s: sum(r.get("status") == s for r in rows) for s in ("ok", "skipped",
                                                                         "failed")}
        hours = sum(float(r.get("wall_time_s") or 0.0) for r in rows
                    if r.get("status") == "ok") / 3600
        devices = sorted({str(r["device"]) for r in rows if r.get("device")})
        out += ["## Runs", "",
                f"{len(rows)} runs: {n_status['ok']} trained now, {n_status['skipped']} found "
                f"finished, {n_status['failed']} failed; {hours:.2f} h of training and testing "
                f"in this invocation" + (f" on {', '.join(devices)}" if devices else "") + ".",
                ""]
    if failed:
        out += ["Failed runs:", ""]
        for r in sorted(failed, key=lambda r: (str(r.get("condition")), r.get("fraction") or 0,
                                               r.get("trial") or 0)):
            err = " ".join(str(r.get("error") or "").split())[:300] or "(no error text)"
            out.append(f"- {r.get('condition')} at {_pct(float(r.get('fraction') or 0))}, "
                       f"trial {r.get('trial')}: {err}")
        out.append("")

    out += ["## Notes", ""] + [f"- {n}" for n in stats["notes"]] + ["", domain_line, ""]
    return "\n".join(out)
