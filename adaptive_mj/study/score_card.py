"""A scorecard written out: scorecard.json (the data), scorecard.md and scorecard.html (the leaderboards, laws as
rows and criteria as columns, the law under test in bold), and per plant a figure of the performance criteria and
one of the margins, each a bar per law with its 95 % interval."""
from __future__ import annotations

import json
import math
from pathlib import Path

from adaptive_mj.study import score_suite as suite
from adaptive_mj.study.result import Table
from adaptive_mj.study.stats import RANKING, Estimate

SCORE_COLUMNS = (("performance", "S"), ("robustness", "R"), ("success", "success"))


def _unit(unit: str, plant: dict) -> str:
    return {"output": plant["output_unit"], "control": plant["control_unit"],
            "control/s": f"{plant['control_unit']}/s"}.get(unit, unit)


def _order(plant: dict) -> list[str]:
    """The plant's laws by performance rank, then by the mean S (best first)."""
    def key(lb: str):
        e = plant["laws"][lb]
        mean = e["figures"]["performance"]["mean"]
        return (e["rank"]["performance"], -(mean if mean is not None and math.isfinite(mean) else -1.0))

    return sorted(plant["laws"], key=key)


def _name(lb: str, e: dict) -> str:
    text = lb + (" †" if e.get("oracle") else "")
    return f"**{text}**" if e.get("tested") else text


def _with_n(est: Estimate, seeds: int) -> str:
    """est's text, with "(n of N seeds)" when runs that diverged or failed to give it left seeds out."""
    return est.text() + (f" ({est.n} of {seeds} seeds)" if est.n < seeds else "")


def leaderboard(plant: dict) -> Table:
    """One row per law (ranked): the ranks, the scores and every criterion with its interval, and the compute
    cost; its to_markdown() is the card's table."""
    cols = ["rank S", "rank R", "law", *(c for _, c in SCORE_COLUMNS),
            *(f"{c.metric} [{_unit(c.unit, plant)}]" for c in suite.CRITERIA), "cost × mj_step"]
    rows = []
    for lb in _order(plant):
        e = plant["laws"][lb]
        f = e["figures"]
        cells = [e["rank"]["performance"], e["rank"]["robustness"], _name(lb, e)]
        seeds = len(f["performance"]["values"])
        for name, _ in SCORE_COLUMNS:
            est = Estimate.from_dict(f[name])
            cells.append(f"{round(est.mean * est.n)}/{seeds}" if name == "success" else est.text())
        cells += [_with_n(Estimate.from_dict(f[c.name]), seeds) for c in suite.CRITERIA]
        ratio = e.get("compute_ratio")
        cells.append("n/a" if ratio is None else f"{ratio:.2f}")
        rows.append(dict(zip(cols, cells, strict=True)))
    return Table.of(rows, cols)


def margins_table(plant: dict) -> Table:
    """One row per law, one column per stressor: the margin's mean [interval] over seeds, and the failure rate at
    the range's high end; its to_markdown() is the card's table."""
    names = [s["name"] for s in plant["stressors"]]
    units = {s["name"]: s["unit"] for s in plant["stressors"]}
    cols = ["law", "R", *(f"{n} [{units[n]}]" if units[n] else n for n in names)]
    rows = []
    for lb in _order(plant):
        e = plant["laws"][lb]
        cells = [_name(lb, e), Estimate.from_dict(e["figures"]["robustness"]).text()]
        for n in names:
            st = e["stressors"].get(n)
            if st is None:
                cells.append("n/a")
                continue
            text = Estimate.from_dict(st["margin"]).text()
            if all(m is not None and ff is None for m, ff in zip(st["margins"], st["first_fails"], strict=True)):
                text = f"≥ {text} (top)"
            elif all(m is None for m in st["margins"]):
                text = f"< {text} (bottom)"
            fr = st.get("failure_rate_at_hi")
            cells.append(text + ("" if fr is None else f"<br>fail@hi {100 * fr:.0f} %"))
        rows.append(dict(zip(cols, cells, strict=True)))
    return Table.of(rows, cols)


def terminal_table(plant: dict) -> Table:
    """The leaderboard as the terminal shows it: both ranks, the law (* under test, † given the true parameters)
    and S and R with their 95 % intervals."""
    rows = []
    for lb in _order(plant):
        e = plant["laws"][lb]
        rows.append({"rank S": e["rank"]["performance"], "rank R": e["rank"]["robustness"],
                     "law": ("* " if e.get("tested") else "  ") + lb + (" †" if e.get("oracle") else ""),
                     "S": Estimate.from_dict(e["figures"]["performance"]).text(".3f"),
                     "R": Estimate.from_dict(e["figures"]["robustness"]).text(".3f")})
    return Table.of(rows, ["rank S", "rank R", "law", "S", "R"])


NOT_APPLIED = Estimate(math.nan, math.nan, math.nan, 0)  # a stressor that does not apply to a law: no bar


def _bars(ax, labels: list[str], ests: list[Estimate], tested: list[bool], title: str, *, log: bool = False) -> None:
    import numpy as np

    y = np.arange(len(labels))
    means = np.array([e.mean if e.n else np.nan for e in ests], dtype=float)
    lo = np.array([e.lo if e.n > 1 and math.isfinite(e.lo) else e.mean for e in ests], dtype=float)
    hi = np.array([e.hi if e.n > 1 and math.isfinite(e.hi) else e.mean for e in ests], dtype=float)
    err = np.vstack([np.clip(means - lo, 0, None), np.clip(hi - means, 0, None)])
    colors = ["tab:red" if t else "tab:blue" for t in tested]
    ax.barh(y, np.nan_to_num(means), xerr=np.nan_to_num(err), color=colors, alpha=0.8, capsize=3)
    ax.set_yticks(y, labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_title(title, fontsize=8)
    ax.tick_params(axis="x", labelsize=7)
    if log and np.all(np.nan_to_num(means) > 0):
        ax.set_xscale("log")


def figures(card_data: dict, out: Path) -> dict[str, list[Path]]:
    """Per plant: <plant>-performance.png (S and each criterion) and <plant>-robustness.png (R and each
    stressor's margin), bars with 95 % intervals; the law under test in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    made: dict[str, list[Path]] = {}
    for pn, plant in card_data["plants"].items():
        labels = _order(plant)
        tested = [bool(plant["laws"][lb].get("tested")) for lb in labels]
        panels = [("performance", "S (higher is better)", False)] + [
            (c.name, f"{c.metric} [{_unit(c.unit, plant)}]", False) for c in suite.CRITERIA]
        fig, axes = plt.subplots(2, 4, figsize=(15, 1.6 + 0.5 * len(labels)), constrained_layout=True)
        for ax, (name, title, log) in zip(axes.flat, panels, strict=True):
            _bars(ax, labels, [Estimate.from_dict(plant["laws"][lb]["figures"][name]) for lb in labels], tested,
                  title, log=log)
        fig.suptitle(f"{pn}: performance criteria, mean and 95 % interval over seeds (lower is better but S)",
                     fontsize=10)
        perf = out / f"{pn}-performance.png"
        fig.savefig(perf, dpi=90)
        plt.close(fig)
        names = [s["name"] for s in plant["stressors"]]
        units = {s["name"]: s["unit"] for s in plant["stressors"]}
        n = 1 + len(names)
        cols = min(4, n)
        rows = math.ceil(n / cols)
        fig, axes = plt.subplots(rows, cols, figsize=(3.8 * cols, rows * (1.4 + 0.4 * len(labels))),
                                 constrained_layout=True, squeeze=False)
        _bars(axes.flat[0], labels, [Estimate.from_dict(plant["laws"][lb]["figures"]["robustness"]) for lb in labels],
              tested, "R (higher is better)")
        spans = {s["name"]: (s["lo"], s["hi"]) for s in plant["stressors"]}
        for ax, name in zip(list(axes.flat)[1:], names, strict=False):
            lo, hi = spans[name]
            _bars(ax, labels, [Estimate.from_dict(plant["laws"][lb]["stressors"][name]["margin"])
                               if name in plant["laws"][lb]["stressors"] else NOT_APPLIED for lb in labels],
                  tested, f"margin: {name} [{units[name]}]", log=lo > 0 and hi / lo >= 10)
        for ax in list(axes.flat)[n:]:
            ax.axis("off")
        fig.suptitle(f"{pn}: breaking points, mean margin and 95 % interval over seeds (higher is better)",
                     fontsize=10)
        rob = out / f"{pn}-robustness.png"
        fig.savefig(rob, dpi=90)
        plt.close(fig)
        made[pn] = [perf, rob]
    return made


def separated_text(data: dict) -> str:
    """How many pairs of laws separate on S and on R, per plant (score.rank_laws' counts)."""
    parts = []
    for pn, plant in data["plants"].items():
        c = plant.get("separated_pairs")
        if c is not None:
            parts.append(f"{pn} S {c['performance']} and R {c['robustness']} of {c['pairs']}")
    return "; ".join(parts) or "none counted"


def formula_text(data: dict) -> str:
    weights = ", ".join(f"{c.name} {c.weight:g} (n: {c.normaliser})" for c in suite.CRITERIA)
    return ("Performance S = c_success · (1 − Σ wᵢ · min(1, cᵢ / nᵢ)) per seed, with the weights and normalisers "
            f"{weights}; c_success = 1 when the tracking, change and hold runs all finished (no divergence) and "
            "the tracking and hold runs kept their tail RMS error within the plant's failure bound. "
            "Robustness R = the mean over the stressors of the margin's "
            "place in the range searched (0: fails at the low end, 1: passes at the high end; geometric over a "
            "decade or more), each margin found by its own bisection per seed "
            f"({data['suite']['steps']} steps after the two ends). Every figure: the mean over "
            f"{data['suite']['seeds']} seeds and its {100 * data['suite']['confidence']:g} % Student-t interval. "
            f"Ranks ({RANKING}): every law runs the same seeds, so two laws are compared seed by seed; they are "
            "separable on S (or R) when the paired t interval of the mean per-seed difference excludes 0 (the seeds' "
            "common variation cancels; seeds where either has no value are left out of that pair), and a rank is 1 + "
            "the number of laws separably better: two copies of one law share a rank (not a grouping: A may tie "
            f"with B and with C while B and C differ). Pairs that separate: {separated_text(data)}. "
            f"{saturated_text(data)}"
            "† a baseline given the true parameters (the fixed and robust "
            "baselines' nominal θ, σ- and e-modification's leakage target θ₀). cost × mj_step: the "
            "closed loop's time per physics step over bare mj_step on the same model (this machine, the best of "
            "3 timings; not in S). docs/METRICS.md, \"Scorecard\", defines each criterion.")


def saturated_text(data: dict) -> str:
    """One sentence: the criteria at their cap for every adaptive law on a plant (score.criteria_spread), or that
    none is."""
    hits = [f"{c} on {pn}" for pn, plant in data["plants"].items()
            for c, sp in (plant.get("criteria_spread") or {}).items() if sp["saturated"]]
    if not hits:
        return ("No criterion is at its cap (cᵢ ≥ nᵢ) for every adaptive law on a plant: each can separate them. ")
    return f"At their cap for every adaptive law, so separating none of them: {', '.join(hits)}. "


def runs_text(data: dict) -> str:
    """What the card ran and did not: every probe run whatever the law (the pre-flight check's predictions
    counted, never taken for a run), and each search left out with why (score.not_run)."""
    runs = data.get("runs") or {}
    text = (f"**Runs.** {runs.get('tasks', 0)} task runs and {runs.get('margins', 0)} margin runs. Every probe is "
            "run and judged by its outcome, whatever the law: the pre-flight check predicted "
            f"{runs.get('predicted_unstable', 0)} of the margin runs unstable (laws that declare their feedback are "
            "checked), and none was refused.")
    left = runs.get("not_run") or []
    if left:
        text += (f" Not run: {len(left)} searches of {left[0]['seeds']} seeds each ("
                 + "; ".join(f"{n['plant']}/{n['law']}: {n['stressor']}" for n in left) + "): " + left[0]["why"] + ".")
    return text


def write_card(card) -> None:
    """scorecard.json, the figures, scorecard.md and scorecard.html into card.out; card.text: the leaderboards."""
    from adaptive_mj.report.html import write_html
    from adaptive_mj.report.metrics import clean_json  # non-finite floats as null: strict JSON

    data, out = card.data, Path(card.out)
    (out / "scorecard.json").write_text(json.dumps(clean_json(data), indent=1, allow_nan=False) + "\n",
                                        encoding="utf-8")
    made = figures(data, out)
    laws = data["law"] if isinstance(data["law"], list) else [data["law"]] if data["law"] else []
    title = " and ".join(f"`{lw['label']}`" for lw in laws) or "the baselines"
    s = data["suite"]
    versions = data["versions"] if isinstance(data["versions"], list) else [data["versions"]]
    head = [f"# adaptive-mj scorecard: {title} against the baselines", "",
            f"Suite `{s['name']}` version {s['version']} (definitions hash `{s['hash']}`), {s['seeds']} seeds, "
            f"margin runs of {s['stress_duration']:g} s, tasks of "
            + ", ".join(f"{k} {v:g} s" for k, v in s["durations"].items()) + "; "
            + "; ".join(", ".join(f"{k} {v}" for k, v in ver.items() if k != "law_plugin") +
                        (f", law plugin {ver['law_plugin']['distribution']} {ver['law_plugin']['version']} "
                         f"(source {ver['law_plugin']['source_sha256'][:12]})" if "law_plugin" in ver else "")
                        for ver in versions)
            + (f"; {data['wall_seconds']:.0f} s wall." if data.get("wall_seconds") else "."), ""]
    body = []
    text = []
    for pn, plant in data["plants"].items():
        body += [f"## {pn} (plant kind {plant['kind']}): leaderboard", "", leaderboard(plant).to_markdown(), "",
                 f"![{pn} performance]({made[pn][0].name})", "", f"### {pn}: breaking points", "",
                 margins_table(plant).to_markdown(), "", f"![{pn} robustness]({made[pn][1].name})", ""]
        text += [f"{pn}:", terminal_table(plant).to_text(left=("law", "S", "R")), ""]
    body += ["## How the card scores", "", formula_text(data), "", runs_text(data), ""]
    (out / "scorecard.md").write_text("\n".join(head + body), encoding="utf-8")
    html = write_html(out / "scorecard.md")
    text.append("*: the law under test; †: a baseline given the true parameters (it knows the answer); S: performance, "
                "R: robustness, each the mean [95 % interval]; a rank is 1 + the number of laws separably better "
                "(paired over the seeds)")
    card.text = "\n".join(text) + f"\n\nscorecard: {out / 'scorecard.md'}\nhtml: {html}\njson: {out / 'scorecard.json'}"


def _cell(e: dict | None) -> str:
    """A law's S and R on one plant, each with its 95 % interval and rank, for the leaderboard page."""
    if e is None:
        return "—"
    f = e["figures"]
    return (f"S {Estimate.from_dict(f['performance']).text('.3f')} (rank {e['rank']['performance']})<br>"
            f"R {Estimate.from_dict(f['robustness']).text('.3f')} (rank {e['rank']['robustness']})")


def write_leaderboard(card, sources: list[dict]) -> Path:
    """A merged card's one page: leaderboard.md and leaderboard.html in card.out, a row per law and a column per
    plant (S and R with their intervals and ranks; † an oracle baseline, given the true parameters), and a link to
    each source card's scorecard.html (relative to card.out). sources: the cards merged (score.read_card's)."""
    import os

    from adaptive_mj.report.html import write_html

    data, out = card.data, Path(card.out)
    plants = list(data["plants"])
    laws: dict[str, dict] = {}
    for pn in plants:  # ranked on the first plant, then the laws only the next ones have
        for lb in _order(data["plants"][pn]):
            laws.setdefault(lb, {})[pn] = data["plants"][pn]["laws"][lb]
    s = data["suite"]
    rows = []
    for lb, by_plant in laws.items():
        e = next(iter(by_plant.values()))
        rows.append({"law": _name(lb, e), **{pn: _cell(by_plant.get(pn)) for pn in plants}})
    lines = ["# adaptive-mj leaderboard", "",
             f"Suite `{s['name']}` version {s['version']} (definitions hash `{s['hash']}`), {s['seeds']} seeds; "
             f"{len(sources)} cards merged. Each cell: S (performance) and R (robustness), the mean [95 % interval] "
             "over seeds and the rank on that plant (1 + the number of laws separably better); **bold**: a law "
             "under test; †: a baseline given the true parameters (an oracle: a reference, not a competitor); —: "
             "not scored on that plant.", "", Table.of(rows, ["law", *plants]).to_markdown(), "", "## Cards", ""]
    for n, src in enumerate(sources, start=1):
        html = Path(src["path"]).resolve().parent / "scorecard.html"
        link = os.path.relpath(html, out.resolve())
        named = src.get("law") or []
        title = " and ".join(lw["label"] for lw in (named if isinstance(named, list) else [named])) or "the baselines"
        lines.append(f"- card {n}: [{title}]({link}) ({src['path']})")
    md = out / "leaderboard.md"
    md.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return write_html(md)
