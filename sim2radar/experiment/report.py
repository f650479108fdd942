"""The sweep's results as text: a Markdown report laid out like the paper's Table 1, and the same
table as rows for a Prefect table artifact; the sentence that says what the sweep could and
could not have detected; the line that says what its "real" data is. Pure functions of
:func:`~.stats.sweep_stats`'s dict (and the run rows, for failures and cost).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from typing import Any

from sim2radar.datasets import UNDECLARED
from sim2radar.experiment.folder import SweepFolder
from sim2radar.experiment.profiles import BASELINE, CONDITIONS
from sim2radar.experiment.stats import DEGENERATE, as_rows

__all__ = ["UNDECLARED", "condition_label", "detectability_sentences", "domain_kind",
           "domain_line", "results_markdown", "results_table_rows"]


_DASH = "—"


def condition_label(condition: str) -> str:
    """Table heading of a condition (``sim-pretrain`` -> ``Sim Pretrain``)."""
    known = CONDITIONS.get(condition)
    return known.label if known else condition


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


def _share(comp: Mapping[str, Any]) -> str:
    """``P(improved)`` with its interval: ``67 % [9, 99]``."""
    share = comp.get("p_improved")
    if share is None:
        return _DASH
    lo, hi = (comp.get("p_improved_ci") or [None, None])[:2]
    ci = "" if lo is None else f" [{100 * lo:.0f}, {100 * hi:.0f}]"
    return f"{100 * share:.0f} %{ci}"


def _mde(comp: Mapping[str, Any]) -> str:
    """The MDE [AP points], or a dash with the short reason there is none."""
    if comp.get("mde") is not None:
        return f"{comp['mde']:.1f}"
    if "mde" not in comp:  # a stats.json written before the MDE existed
        return _DASH
    if comp.get("n_pairs", 0) < 2:
        return f"{_DASH} (< 2 pairs)"
    if comp.get("verdict") == DEGENERATE:
        return f"{_DASH} (sd 0)"
    return _DASH


def _paper_trials(comp: Mapping[str, Any]) -> str:
    """The paper's Δ and the trials that would detect it: ``+3.3 (14)``."""
    delta = comp.get("paper_delta")
    if delta is None:
        return _DASH
    n = comp.get("n_for_paper_delta")
    if n is not None:
        return f"{delta:+.1f} ({n:,})"
    note = str(comp.get("n_for_paper_delta_note") or "")
    if note.startswith("more than "):  # "more than 100,000 trials"
        return f"{delta:+.1f} (> {note.split()[2]})"
    return f"{delta:+.1f} ({_DASH})"


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
    ``Δ``, ``95 % CI`` (Student t, unadjusted), ``simultaneous CI`` (the ``1 - alpha / m``
    Student-t interval over the condition's m fractions, the one the Holm verdict agrees
    with), ``MDE`` (minimum detectable effect at 80 % power [AP
    points]; a dash with the reason where there is none), ``p (Holm)``, ``d_z``, ``k/n``,
    ``P(improved)`` (k/n as a percentage with its Clopper–Pearson interval), ``verdict``,
    ``paper Δ (trials)`` (the paper's Δ at the fraction and the trials that would detect it at
    the observed spread), ``bootstrap CI`` (reference only: anti-conservative at few pairs).
    APs as ``mean ± std`` (sample std over trials), Δ = condition minus baseline. Reads a
    ``stats.json`` written before the MDE existed (dashes).
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
        s_lo, s_hi = comp.get("t_ci_simultaneous") or [None, None]
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
            "simultaneous CI": _DASH if s_lo is None
            else f"[{_f(s_lo, signed=True)}, {_f(s_hi, signed=True)}]",
            "MDE": _mde(comp),
            "p (Holm)": _p(comp["p_holm"]),
            "d_z": _f(comp["d_z"], 2),
            "k/n": f"{comp['k_improved']}/{comp['n_pairs']}",
            "P(improved)": _share(comp),
            "verdict": comp["verdict"],
            "paper Δ (trials)": _paper_trials(comp),
            "bootstrap CI": _DASH if b_lo is None
            else f"[{_f(b_lo, signed=True)}, {_f(b_hi, signed=True)}]"
            + (f" ({100 * comp['bootstrap_coverage']:.0f} % cov.)"
               if comp.get("bootstrap_coverage") is not None else ""),
        })
    return rows


def _range(values: list[float], fmt: str = ".1f", signed: bool = False) -> str:
    """``4.1`` or ``4.1 to 27.0`` (``+0.9 to +3.7`` signed)."""
    spec = ("+" if signed else "") + fmt
    lo, hi = min(values), max(values)
    return format(lo, spec) if format(lo, spec) == format(hi, spec) else \
        f"{format(lo, spec)} to {format(hi, spec)}"


def _fractions(fracs: list[float]) -> str:
    return ", ".join(_pct(f) for f in fracs)


def detectability_sentences(stats: Mapping[str, Any]) -> list[str]:
    """One sentence per non-baseline condition: what the sweep could and could not have
    detected, computed from the comparisons' MDEs and the paper's Δ (:func:`~.stats
    .sweep_stats`'s ``mde``, ``paper_delta``, ``n_for_paper_delta``).

    E.g. "Sim Pretrain vs Baseline: with 3 trials per fraction this sweep could detect gains
    of ≥ 4.1 AP points (at 100 %) to ≥ 27.0 (at 5 %) at 80 % power; the paper's effects (+0.9
    to +3.7) are below that at every fraction; detecting them at the observed spread would
    take 12 to 240 trials per fraction." Empty for a ``stats.json`` written before the MDE
    existed.
    """
    comps = list(stats.get("comparisons", []))
    if not comps or not all("mde" in c for c in comps):
        return []
    power = float((stats.get("power") or {}).get("power", 0.8))
    out = []
    for cond in dict.fromkeys(c["condition"] for c in comps):
        block = [c for c in comps if c["condition"] == cond]
        head = f"{condition_label(cond)} vs {condition_label(BASELINE)}: "
        with_mde = [c for c in block if c.get("mde") is not None]
        if not with_mde:
            flat = [c for c in block if c.get("verdict") == DEGENERATE]
            why = ("every fraction's paired differences are identical (sd 0)" if flat and
                   len(flat) == len(block) else "no fraction has 2 complete pairs whose "
                   "differences vary")
            out.append(head + f"this sweep cannot say what it could have detected: {why}.")
            continue
        ns = sorted({c["n_pairs"] for c in with_mde})
        trials = (f"{ns[0]} trials" if len(ns) == 1 else f"{ns[0]} to {ns[-1]} trials")
        lo = min(with_mde, key=lambda c: c["mde"])
        hi = max(with_mde, key=lambda c: c["mde"])
        if f"{lo['mde']:.1f}" == f"{hi['mde']:.1f}":
            gains = f"≥ {lo['mde']:.1f} AP points"
        else:
            gains = (f"≥ {lo['mde']:.1f} AP points (at {_pct(lo['fraction'])}) to "
                     f"≥ {hi['mde']:.1f} (at {_pct(hi['fraction'])})")
        text = (head + f"with {trials} per fraction this sweep could detect gains of {gains} "
                f"at {100 * power:g} % power")
        papered = [c for c in with_mde if c.get("paper_delta") is not None]
        if papered:
            deltas = [c["paper_delta"] for c in papered]
            below = [c for c in papered if abs(c["paper_delta"]) < c["mde"]]
            above = [c["fraction"] for c in papered if abs(c["paper_delta"]) >= c["mde"]]
            many = len(papered) > 1
            effects = f"the paper's effect{'s' if many else ''} ({_range(deltas, signed=True)})"
            if not above:
                text += (f"; {effects} {'are' if many else 'is'} below that"
                         + (" at every fraction" if many else ""))
            elif not below:
                text += (f"; {effects} {'are' if many else 'is'} at or above it"
                         + (" at every fraction" if many else ""))
            else:
                text += (f"; {effects} are below it at "
                         f"{_fractions([c['fraction'] for c in below])} and at or above it at "
                         f"{_fractions(above)}")
            needed = [float(c["n_for_paper_delta"]) for c in below
                      if c.get("n_for_paper_delta") is not None]
            if needed:
                text += (f"; detecting {'them' if len(below) > 1 else 'it'} at the observed "
                         f"spread would take {_range(needed, ',.0f')} trials per fraction")
        skipped = [c["fraction"] for c in block if c.get("mde") is None]
        if skipped:
            text += f" (no MDE at {_fractions(skipped)}: fewer than 2 pairs or no spread)"
        out.append(text + ".")
    return out


def _primary_section(stats: Mapping[str, Any], level: str, power: float) -> list[str]:
    """The pre-registered primary endpoint: the pooled Δ per condition, the primary first."""
    pooled = list(stats.get("pooled") or [])
    if not pooled:
        return []
    fracs = ", ".join(_pct(f) for f in pooled[0]["fractions"])
    out = ["## Primary endpoint: Δ pooled over the low-data fractions", "",
           f"Per trial, the mean of the paired Δ at {fracs}; then the mean over trials with its "
           f"{level} (Student t, one pre-registered test at alpha = "
           f"{float(stats['alpha']):g}), its MDE at {100 * power:g} % power and the verdict. "
           "Rows other than the primary are diagnostics at the same unadjusted level.", ""]
    header = ["Condition", "role", "trials", condition_label(BASELINE), "Condition",
              f"Δ [{level}]", "MDE", "p", "d_z", "k/n", "Verdict"]
    body = []
    for c in sorted(pooled, key=lambda c: not c["primary"]):
        lo, hi = c["t_ci"]
        ci = "" if lo is None else f" [{_f(lo, signed=True)}, {_f(hi, signed=True)}]"
        mde = _f(c["mde"]) if c.get("mde") is not None else (
            f"{_DASH} (< 2 pairs)" if c["n_pairs"] < 2 else _DASH)
        body.append([condition_label(c["condition"]),
                     "**primary**" if c["primary"] else "diagnostic", str(c["n_pairs"]),
                     _f(c["baseline_mean"]), _f(c["condition_mean"]),
                     f"{_f(c['mean_diff'], signed=True)}{ci}", mde, _p(c["p"]), _f(c["d_z"], 2),
                     f"{c['k_improved']}/{c['n_pairs']}", c["verdict"]])
    out += _table(header, body, ["l", "l", "r", "r", "r", "l", "r", "r", "r", "r", "l"])
    return out + [""]


def _pretraining_section(pre: Mapping[str, Any] | None) -> list[str]:
    """Every pre-training's check: the summary per condition, then one row each."""
    if not pre or not pre.get("rows"):
        return []
    out = ["## Pre-trainings: what each learned before fine-tuning", "",
           "3D AP (R40, IoU 0.3, %) of the pre-trained detector (encoder and head, no "
           "fine-tuning) on its own simulated training frames, on the held-out simulated split "
           "(worlds it never saw), and zero-shot on the real validation split. A threshold is "
           "the pre-registered held-out AP a condition's pre-trainings were expected to reach; "
           "it is reported, never used to select or drop a run.", ""]

    def ms(d: Mapping[str, Any]) -> str:
        if d.get("mean") is None:
            return _DASH
        return _f(d["mean"]) if d.get("std") is None else f"{d['mean']:.1f} ± {d['std']:.1f}"

    body = []
    for s in pre.get("summary", []):
        thr = _DASH if s["threshold"] is None else (
            f"{s['threshold']:.1f} (met {s['n_met']}/{s['n']})")
        body.append([condition_label(s["condition"]), s["role"], str(s["n"]),
                     str(s["n_failed"]), ms(s["train"]), ms(s["heldout"]), ms(s["zero_shot"]),
                     thr])
    out += _table(["Condition", "dataset", "pre-trainings", "failed", "train AP",
                   "held-out sim AP", "zero-shot real AP", "threshold"], body,
                  ["l", "l", "r", "r", "r", "r", "r", "l"]) + [""]
    body = []
    for r in pre["rows"]:
        met = ", ".join(f"{c}: {'met' if v else 'not met'}" for c, v in r["met"].items()
                        if v is not None) or _DASH
        body.append([str(r["id"]), str(r["n_sim_frames"]), str(r["n_heldout_frames"]),
                     _f(r["train"]), _f(r["heldout"]), _f(r["zero_shot"]),
                     _f(r["final_loss"], 3), met,
                     r["status"] if r["status"] != "failed" else f"failed: {r['error'][:120]}"])
    out += ["<details><summary>Every pre-training</summary>", ""]
    out += _table(["Pre-training", "sim frames", "held-out frames", "train AP",
                   "held-out sim AP", "zero-shot real AP", "final loss", "threshold", "status"],
                  body, ["l", "r", "r", "r", "r", "r", "r", "l", "l"])
    return out + ["", "</details>", ""]


def domain_kind(label: str, proxy: bool | None = None) -> str:
    """What a dataset's declared ``domain`` says it is: ``"proxy"`` (a labelled stand-in for
    measured radar: ``proxy`` is True, or the label starts with "proxy"), ``"undeclared"``
    (empty, or :data:`UNDECLARED`), ``"measured"`` (the word "measured" in the label, e.g.
    "measured", "IFR (measured)"), else ``"declared"`` (another declared domain, e.g.
    "synthetic (detect-demo-data)": not measured radar)."""
    text = (label or "").strip().lower()
    if proxy or (proxy is None and text.startswith("proxy")):
        return "proxy"
    if not text or text == UNDECLARED:
        return "undeclared"
    if re.search(r"\bmeasured\b", text):
        return "measured"
    return "declared"


def domain_line(label: str, proxy: bool | None = None) -> str:
    """The report's line on the real domain (:func:`domain_kind`)."""
    kind = domain_kind(label, proxy)
    if kind == "proxy":
        return (f"**real = {label}**: a stand-in for measured radar. These results are not "
                "claims about measured radar.")
    if kind == "undeclared":
        return ("**real = undeclared**: the real dataset's `dataset.json` declares no domain, so "
                "this report cannot say whether it is measured radar. Declare it (e.g. "
                '`{"domain": "measured"}`) before reading these results as claims about '
                "measured radar.")
    if kind == "measured":
        return f"real = {label} (measured radar)."
    return (f"**real = {label}** (as its `dataset.json` declares): not measured radar. These "
            "results are not claims about measured radar.")


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
    settings: Mapping[str, Any] | None = None,
    preregistration: Mapping[str, Any] | None = None,
) -> str:
    """A Markdown report of a sweep.

    Parameters
    ----------
    stats : :func:`~sim2radar.experiment.stats.sweep_stats` output.
    runs : the ``experiment_runs`` rows (list of dicts or a pyarrow Table), for the failed runs'
        errors and the sweep's cost; may be empty.
    title : the report's heading.
    real_domain_label : what the "real" data is, as its ``dataset.json`` declares, e.g.
        ``"proxy-real (reference radar simulation)"``, ``"IFR (measured)"``, ``"synthetic
        (detect-demo-data)"``, or ``"undeclared"``.
    proxy : whether the real domain is a stand-in for measured radar (default: the label
        starts with ``proxy``). A proxy, undeclared or other non-measured domain says so at the
        top and at the end (:func:`domain_line`); only a domain declared "measured" is called
        measured radar.
    settings : ``{"profile", "digest", "fixed_at"}`` from sweep.json: the line saying when the
        sweep's settings were fixed (before its first run; a changed profile is refused).
    preregistration : ``{"file", "sha256"}`` from sweep.json: the pre-registration the report
        links (its copy beside the report).

    Returns
    -------
    str — the pre-registered primary endpoint (the pooled Δ over the low-data fractions, with
    its interval, MDE and verdict), what the sweep could detect per fraction
    (:func:`detectability_sentences`), the pre-trainings' checks, Table 1 (one block per
    non-baseline condition, secondary, Holm-adjusted) with the MDE beside every Δ and verdict,
    every trial's value per cell, failed runs, notes, and the real domain's status.
    """
    line = domain_line(real_domain_label, proxy)
    cells = _cells(stats)
    alpha = float(stats["alpha"])
    level = f"{100 * (1 - alpha):g} % CI"
    power = float((stats.get("power") or {}).get("power", 0.8))
    out = [f"# {title}", "", line, "",
           f"Metric: `{stats['metric']}` (AP in %), mean ± std over trials; Δ = condition "
           f"minus baseline, paired by trial, with its {level} (Student t); MDE = the "
           f"smallest true Δ detected with {100 * power:g} % power at the Holm family's level "
           f"(AP points); p Holm-adjusted across fractions; verdict at alpha = {alpha:g}; "
           "P(improved) = k/n with its Clopper–Pearson interval; paper Δ (trials) = the "
           "paper's Table 1 Δ and the trials that would detect it at the observed spread.", ""]
    if settings:
        out += [f"Settings: profile `{settings.get('profile', '?')}` (digest "
                f"`{settings.get('digest', '?')}`), fixed at {settings.get('fixed_at', '?')}, "
                "before any run of this sweep; a rerun with changed settings is refused.", ""]
    if preregistration:
        file = preregistration.get("file", SweepFolder.PREREGISTRATION)
        out += [f"Pre-registration: [{file}]({file}) (SHA-256 "
                f"`{str(preregistration.get('sha256', '?'))[:16]}…`, part of the settings: "
                "it cannot change once the sweep has started).", ""]
    out += _primary_section(stats, level, power)
    out += [f"- {s}" for s in detectability_sentences(stats)]
    if out[-1] != "":
        out.append("")
    out += _pretraining_section(stats.get("pretrainings"))

    rows_by_cond: dict[str, list[dict[str, str]]] = {}
    for row in results_table_rows(stats):
        rows_by_cond.setdefault(row["condition"], []).append(row)
    secondary = "secondary, " if stats.get("pooled") else ""
    for cond, rows in rows_by_cond.items():
        label = condition_label(cond)
        out += [f"## {label} vs {condition_label(BASELINE)} per fraction ({secondary}"
                "Holm-adjusted)", ""]
        header = ["Real Data", "N", "Sim:Real", condition_label(BASELINE), label,
                  f"Δ [{level}, unadjusted]", "simultaneous CI", "MDE", "p (Holm)", "d_z",
                  "k/n", "P(improved)", "Verdict", "Paper Δ (trials)", "Bootstrap CI (ref.)"]
        body = [[r["real data"], r["N"], r["Sim:Real"], r["baseline"], r["condition AP"],
                 f"{r['Δ']} {r[level]}" if r[level] != _DASH else r["Δ"],
                 r["simultaneous CI"], r["MDE"], r["p (Holm)"], r["d_z"], r["k/n"],
                 r["P(improved)"], r["verdict"], r["paper Δ (trials)"], r["bootstrap CI"]]
                for r in rows]
        out += _table(header, body, ["r", "r", "r", "r", "r", "l", "l", "r", "r", "r", "r",
                                     "r", "l", "r", "l"])
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

    out += ["## Notes", ""] + [f"- {n}" for n in stats["notes"]] + ["", line, ""]
    return "\n".join(out)
