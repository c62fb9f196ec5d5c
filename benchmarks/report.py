"""Tables and the time-against-error plot of benchmarks/accuracy.py."""
from __future__ import annotations

import math

COLUMNS = [("model", "model"), ("cloud", "cloud"), ("points", "points"), ("renderer", "renderer"),
           ("method", "method"), ("closed", "closed"), ("seconds", "time (s)"), ("cores", "cores"),
           ("silhouette_px", "silhouette err (px)"), ("missing_px", "missing (px)"), ("extra_px", "extra (px)"),
           ("normal_mean_deg", "normal err mean (°)"),
           ("normal_p95_deg", "normal err p95 (°)"), ("depth_mean_rel", "depth err (% size)"),
           ("wrong_surface_pct", "wrong surface (%)")]
SUMMARY_METHODS = {"general", "nearest-centre", "full"}


def _fmt(key, value):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if key == "seconds":
        return f"{value:.3f}" if value < 1 else f"{value:.2f}"
    if key == "cores":
        return f"{value:.1f}" if isinstance(value, float) else str(value)
    if key == "depth_mean_rel":
        return f"{100 * value:.3f}"
    if key in ("normal_mean_deg", "normal_p95_deg", "wrong_surface_pct"):
        return f"{value:.2f}"
    if key.endswith("_px"):
        return f"{value:,.0f}"
    if key == "points":
        return f"{value:,}"
    if key == "closed":
        return "yes" if value else "no"
    return str(value)


def table(rows) -> str:
    lines = ["| " + " | ".join(title for _, title in COLUMNS) + " |",
             "|" + "|".join("---" if k in ("model", "cloud", "renderer", "method") else "---:" for k, _ in COLUMNS) + "|"]
    for r in rows:
        if r.get("renderer", "").startswith("paper"):
            cells = [r["model"], r["cloud"], f"{r['points']:,}", r["renderer"], r["method"], "yes",
                     r["seconds_range"], "?"] + ["–"] * (len(COLUMNS) - 8)
        else:
            cells = [_fmt(k, r.get(k)) for k, _ in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def summary(rows) -> str:
    """The presets at default settings, the Blender renders and the paper: the README's table."""
    keep = [r for r in rows if r.get("renderer") != "splat_tracer core" or r.get("method") in SUMMARY_METHODS]
    return table(keep)


README_CLOUDS = [("stanford-bunny", "vertices"), ("fandisk", "samples 50k"), ("cube", "vertices"),
                 ("torus", "samples 50k"), ("spot", "samples 50k")]


def readme_table(rows) -> str:
    """The README's selection: the paper's experiment (the bunny's vertices), fandisk's sharp
    edges, and three more models; the presets at default settings, the full method with the
    cloud forced closed, Blender's own render, Cycles and the paper."""
    keep = []
    for model, cloud in README_CLOUDS:
        for r in rows:
            if (r.get("model"), r.get("cloud")) != (model, cloud):
                continue
            if r.get("renderer") != "splat_tracer core" or r.get("method") in SUMMARY_METHODS | {"full, forced closed"}:
                keep.append(r)
    return table(keep)


AGGREGATED = ("silhouette_px", "missing_px", "extra_px", "normal_mean_deg", "normal_p95_deg", "depth_mean_rel",
              "wrong_surface_pct")


def per_method(rows) -> str:
    """One row per core preset over every model and cloud: the mean and the worst of each
    error, and how often the full method is no worse than nearest-centre (within 2 %)."""
    core_rows = [r for r in rows if r.get("renderer") == "splat_tracer core" and r.get("method") in SUMMARY_METHODS]
    lines = ["| method | over | " + " | ".join(dict(COLUMNS)[k] for k in AGGREGATED) + " |",
             "|---|---|" + "---:|" * len(AGGREGATED)]
    for method in ("general", "nearest-centre", "full"):
        mine = [r for r in core_rows if r["method"] == method]
        if not mine:
            continue
        for name, fn in (("mean", lambda v: sum(v) / len(v)), ("worst", max)):
            cells = [_fmt(k, fn([r[k] for r in mine if r.get(k) is not None and r[k] == r[k]])) for k in AGGREGATED]
            lines.append(f"| {method} | {name} of {len(mine)} | " + " | ".join(cells) + " |")
    full = {(r["model"], r["cloud"]): r for r in core_rows if r["method"] == "full"}
    near = {(r["model"], r["cloud"]): r for r in core_rows if r["method"] == "nearest-centre"}
    checks = []
    for key in sorted(full.keys() & near.keys()):
        worse = [k for k in ("silhouette_px", "normal_mean_deg", "wrong_surface_pct")
                 if full[key][k] > near[key][k] * 1.02 + (2 if k == "silhouette_px" else 0.01)]
        if worse:
            checks.append(f"{key[0]} ({key[1]}): " + ", ".join(worse))
    verdict = ("full is no worse than nearest-centre on every model in silhouette, mean normal and wrong-surface "
               "error (2 % noise allowed)" if not checks else "full worse than nearest-centre on: " + "; ".join(checks))
    return "\n".join(lines) + "\n\n" + verdict + "\n"


def markdown(rows) -> str:
    return ("# Run time against error\n\nMade by `python -m benchmarks.accuracy` (see its docstring for what "
            "each column measures).\n\n## Per method, over every model\n\n" + per_method(rows) +
            "\n## Summary\n\n" + summary(rows) + "\n## Every configuration\n\n" + table(rows))


def plot(rows, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = [r for r in rows if not r.get("renderer", "").startswith("paper")]
    groups = sorted({(r["model"], r["cloud"]) for r in data})
    cols = min(3, len(groups))
    nrows = math.ceil(len(groups) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(5 * cols, 3.6 * nrows), squeeze=False)
    styles = {"general": ("tab:red", "o"), "nearest-centre": ("tab:orange", "s"), "full": ("tab:green", "D"),
              "sweep": ("tab:olive", "."), "blender": ("tab:blue", "^"), "cycles": ("tab:purple", "v")}

    def style(r):
        if r["renderer"].startswith("Cycles"):
            return "cycles"
        if r["renderer"].startswith("splat_tracer in Blender"):
            return "blender"
        return r["method"] if r["method"] in SUMMARY_METHODS else "sweep"

    for ax, (model, cloud) in zip(axes.ravel(), groups):
        for r in data:
            if (r["model"], r["cloud"]) != (model, cloud):
                continue
            colour, marker = styles[style(r)]
            ax.scatter(r["seconds"], r["normal_mean_deg"], c=colour, marker=marker, s=36,
                       label=style(r), edgecolors="none")
        ax.set_xscale("log")
        ax.set_title(f"{model}, {cloud}", fontsize=10)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("mean normal error (°)")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(groups):]:
        ax.axis("off")
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), frameon=False)
    fig.suptitle("Run time against error (lower left is better); paper: 7-10 s for the bunny at 640x480")
    fig.tight_layout(rect=(0, 0.05, 1, 0.96))
    fig.savefig(path, dpi=90)
    plt.close(fig)
