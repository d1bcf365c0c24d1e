"""PNG figures of the experiment reports (matplotlib, the optional `experiments` extra). Every figure
names its number of seeds and a spread (min-max over seeds of the final evaluation)."""
from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Sequence

import numpy as np

from tracelab.train.experiments.stats import spread

# deferred: matplotlib, an optional extra (tracelab[experiments]), imported when a plot is drawn (pyplot after
# matplotlib.use, as matplotlib asks)

ARM_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")


def _pyplot():
    try:
        import matplotlib
    except ImportError as e:
        raise RuntimeError("the experiment plots need matplotlib: pip install 'tracelab[experiments]'") from e
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def seed_mean_band(seeds: Sequence[tuple[int, np.ndarray, np.ndarray]]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """(steps, mean, low, high) over the seeds at the steps every seed evaluated: the mean and its 95%
    t-interval over seeds (stats.spread, as the reports' text gives it). None with fewer than two seeds
    or no step in common."""
    curves = [(np.asarray(st), np.asarray(v, float)) for _, st, v in seeds if len(st)]
    if len(curves) < 2:
        return None
    common = curves[0][0]
    for st, _ in curves[1:]:
        common = np.intersect1d(common, st)
    if len(common) == 0:
        return None
    at = np.array([v[np.searchsorted(st, common)] for st, v in curves])  # [seeds, steps]
    stats = [spread(at[:, j]) for j in range(len(common))]
    return (common, np.array([s["mean"] for s in stats]), np.array([s["ci_low"] for s in stats]),
            np.array([s["ci_high"] for s in stats]))


def learning_curves(path: Path, arms: Sequence[dict], *, metric: str, ylabel: str, title: str,
                    percent: bool, small: bool = False) -> Path:
    """One thin line per seed per arm of `metric` against training steps, with the seeds' mean as a
    thick line and its 95% interval over seeds as a band; the arm's published figure as a dashed line.
    `arms`: [{"label", "published" (or None), "seeds": [(seed, steps, values)]}]."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.4) if small else (10.0, 5.0), dpi=100)
    draw_learning_curves(ax, arms, ylabel=ylabel, title=title, percent=percent, small=small)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def draw_learning_curves(ax, arms: Sequence[dict], *, ylabel: str, title: str, percent: bool,
                         small: bool = False) -> None:
    """learning_curves' drawing onto the matplotlib axes `ax`."""
    scale = 100.0 if percent else 1.0
    legend_bits, last_step = [], 0.0
    for i, arm in enumerate(arms):
        colour = ARM_COLOURS[i % len(ARM_COLOURS)]
        finals = []
        for k, (seed, steps, values) in enumerate(arm["seeds"]):
            if len(steps) == 0:
                continue
            ax.plot(steps, values * scale, color=colour, alpha=0.45, lw=0.9, marker="o", ms=2,
                    ls=("-", "--", ":", "-.")[k % 4], label=f"{arm['label']}, seed {seed}")
            finals.append(values[-1] * scale)
            last_step = max(last_step, float(steps[-1]))
        band = seed_mean_band(arm["seeds"])
        if band is not None:
            at, mean, low, high = band
            lo_clip, hi_clip = (0.0, 100.0) if percent else (-np.inf, np.inf)  # a rate's interval stays a rate
            ax.fill_between(at, np.clip(low * scale, lo_clip, hi_clip), np.clip(high * scale, lo_clip, hi_clip),
                            color=colour, alpha=0.18, lw=0, label=f"{arm['label']}, 95% CI of the mean")
            ax.plot(at, mean * scale, color=colour, lw=2.6, label=f"{arm['label']}, mean of {len(finals)} seeds")
        if finals:
            unit = "%" if percent else ""
            legend_bits.append(f"{arm['label']}: last point min {min(finals):.1f}{unit}, max {max(finals):.1f}{unit} "
                               f"over {len(finals)} seed{'s' if len(finals) != 1 else ''}")
    published = [(a["published"], i) for i, a in enumerate(arms) if a.get("published") is not None]
    for value in sorted({v for v, _ in published}):  # one line per figure: arms may share the method's
        owners = [i for v, i in published if v == value]
        colour = ARM_COLOURS[owners[0] % len(ARM_COLOURS)] if len(owners) == 1 else "k"
        ax.axhline(value * scale, color=colour, ls=(0, (6, 3)), lw=1.2, alpha=0.6,
                   label=f"the method: {value * scale:.1f}{'%' if percent else ''}")
    ax.set_xlim(0, max(last_step, 1.0) * 1.03)
    ax.set_xlabel("training steps")
    ax.set_ylabel(ylabel)
    if percent:
        ax.set_ylim(-2, 102)
    ax.xaxis.set_major_formatter(_thousands())
    ax.grid(alpha=0.3)
    _title(ax, [title, *legend_bits], small)
    ax.legend(fontsize=6 if small else 8, loc="upper left", bbox_to_anchor=(1.01, 1.0), framealpha=0.85)


def paired_bars(path: Path, groups: Sequence[str], series: dict[str, Sequence[tuple[float, float, float]]],
                *, ylabel: str, title: str, reference: float | None = None, small: bool = False) -> Path:
    """Grouped bars with error bars: series name -> per group (value, low, high), in percent."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.4) if small else (10.0, 5.0), dpi=100)
    x = np.arange(len(groups))
    width = 0.8 / max(1, len(series))
    for i, (name, vals) in enumerate(series.items()):
        v = np.array([a for a, _, _ in vals]) * 100
        err = np.array([[a - lo, hi - a] for a, lo, hi in vals]).T * 100
        bars = ax.bar(x + (i - (len(series) - 1) / 2) * width, v, width, yerr=err, capsize=3,
                      color=ARM_COLOURS[i % len(ARM_COLOURS)], alpha=0.85, label=name)
        # readable at 0% too; upright when three or more bars stand side by side (they would overlap)
        ax.bar_label(bars, fmt="%.1f", fontsize=6 if small else 8, padding=2, rotation=90 if len(series) > 2 else 0)
    if reference is not None:
        ax.axhline(reference * 100, color="k", ls=(0, (6, 3)), lw=1, alpha=0.6,
                   label=f"the method: {reference * 100:.1f}%")
    ax.set_xticks(x, groups, fontsize=8)
    ax.set_ylabel(ylabel)
    ax.set_ylim(0, 112 if len(series) > 2 else 105)  # room for the upright labels above 100%
    ax.grid(alpha=0.3, axis="y")
    _title(ax, [title], small)
    ax.legend(fontsize=6 if small else 8, loc="upper left", bbox_to_anchor=(1.01, 1.0), framealpha=0.85)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def _title(ax, lines: Sequence[str], small: bool) -> None:
    width = 65 if small else 85  # characters that fit over the axes (the legend takes the right)
    ax.set_title("\n".join(textwrap.fill(t, width) for t in lines if t), fontsize=7 if small else 10)


def _thousands():
    from matplotlib.ticker import FuncFormatter
    return FuncFormatter(lambda v, _: f"{v / 1000:g}K" if abs(v) >= 1000 else f"{v:g}")
