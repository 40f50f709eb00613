#!/usr/bin/python3
"""Regenerates the validation figures and tables in docs/ from the built CLI and tests.

Usage (after building): /usr/bin/python3 scripts/make-validation-plots.py
Needs Debian's python3-matplotlib (bash scripts/install-deps.sh --docs). Writes docs/images/*.png and
docs/generated/validation-tables.md; every number there comes from a run made by this script.
"""
import json
import math
import os
import platform
import re
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CLI = os.path.join(ROOT, "build", "apps", "fluorosim")
TESTS = os.path.join(ROOT, "build", "tests", "fluorosim_tests")
IMAGES = os.path.join(ROOT, "docs", "images")
GENERATED = os.path.join(ROOT, "docs", "generated")


def run_slab(case, photons, seed=20261121, threads=0):
    args = [CLI, "validate", "slab", "--quiet",
            "--mua", str(case["mua_per_cm"]), "--mus", str(case["mus_per_cm"]), "--g", str(case["g"]),
            "--thickness", str(case["thickness_cm"]), "--n", str(case["n"]),
            "--n-above", str(case["n_above"]), "--n-below", str(case["n_below"]),
            "--photons", str(photons), "--seed", str(seed), "--threads", str(threads)]
    return json.loads(subprocess.run(args, check=True, capture_output=True, text=True).stdout)


def slab_table():
    cases = json.load(open(os.path.join(ROOT, "tests", "data", "slab_references.json")))["cases"]
    rows, names, zr, zt = [], [], [], []
    for c in cases:
        r = run_slab(c, 1000000)
        def z(key):
            ref = c[key]
            if ref is None:
                return None
            return (r[key] - ref) / math.sqrt(r[key + "_stderr"] ** 2 + c["reference_accuracy"] ** 2 / 4)
        names.append(c["name"])
        zr.append(z("Rd"))
        zt.append(z("Tt"))
        rows.append((c, r))
    fig, ax = plt.subplots(figsize=(9, 4.8))
    x = range(len(names))
    ax.bar([i - 0.2 for i in x], [v if v is not None else 0 for v in zr], width=0.4, label="Rd")
    ax.bar([i + 0.2 for i in x], [v if v is not None else 0 for v in zt], width=0.4, label="Tt")
    for lim in (-4, 4):
        ax.axhline(lim, color="red", lw=0.8, ls="--")
    ax.axhline(0, color="black", lw=0.5)
    ax.set_xticks(list(x))
    ax.set_xticklabels(names, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("(Fluorosim - reference) / combined std. error")
    ax.set_title("Slab validator against published and closed-form references (1e6 photons each)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(IMAGES, "slab_zscores.png"), dpi=110)
    plt.close(fig)
    lines = ["| case | mua /cm | mus /cm | g | d cm | n (above/below) | Rd ref | Rd ours ± se | Tt ref | Tt ours ± se | source kind |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for c, r in rows:
        def fmt(key):
            return "—" if c[key] is None else f"{c[key]:.6f}"
        lines.append(f"| {c['name']} | {c['mua_per_cm']} | {c['mus_per_cm']} | {c['g']} | {c['thickness_cm']} | "
                     f"{c['n']} ({c['n_above']}/{c['n_below']}) | {fmt('Rd')} | {r['Rd']:.6f} ± {r['Rd_stderr']:.6f} | "
                     f"{fmt('Tt')} | {r['Tt']:.6f} ± {r['Tt_stderr']:.6f} | {c.get('kind', '')} |")
    worst = max(abs(v) for v in zr + zt if v is not None)
    lines.append("")
    lines.append(f"Largest |z| over all cases: {worst:.2f} (acceptance: 4).")
    return "\n".join(lines)


def convergence():
    case = {"mua_per_cm": 10, "mus_per_cm": 90, "g": 0.75, "thickness_cm": 0.02, "n": 1, "n_above": 1, "n_below": 1}
    ns, errs, ses, secs = [], [], [], []
    for n in [10 ** 3, 10 ** 4, 10 ** 5, 10 ** 6, 10 ** 7]:
        r = run_slab(case, n, seed=7)
        ns.append(n)
        errs.append(abs(r["Rd"] - 0.09739))
        ses.append(r["Rd_stderr"])
        secs.append(r["seconds"])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.loglog(ns, ses, "o-", label="reported standard error of Rd")
    ax.loglog(ns, errs, "s--", label="|Rd - van de Hulst 0.09739|")
    ax.loglog(ns, [ses[0] * math.sqrt(ns[0] / n) for n in ns], ":", color="gray", label="N^-1/2")
    ax.set_xlabel("photons")
    ax.set_ylabel("error")
    ax.set_title("MCML classic case: error against photon count")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(IMAGES, "slab_convergence.png"), dpi=110)
    plt.close(fig)
    lines = ["| photons | Rd error | reported stderr | seconds |", "| --- | --- | --- | --- |"]
    for n, e, s, t in zip(ns, errs, ses, secs):
        lines.append(f"| {n:.0e} | {e:.2e} | {s:.2e} | {t:.3f} |")
    return "\n".join(lines)


def rough_glass():
    out = subprocess.run([TESTS, "--gtest_filter=Furnace.RoughGlass*"], capture_output=True, text=True).stdout
    pts = [(float(a), float(m), float(s)) for a, m, s in re.findall(r"alpha ([\d.]+) -> ([\d.]+) \+- ([\d.]+)", out)]
    return "\n".join(["| GGX alpha | furnace radiance / field | std. error |", "| --- | --- | --- |"] +
                     [f"| {a} | {m:.4f} | {s:.4f} |" for a, m, s in pts])


def main():
    if not os.path.exists(CLI):
        sys.exit("build first: bash scripts/build.sh")
    os.makedirs(IMAGES, exist_ok=True)
    os.makedirs(GENERATED, exist_ok=True)
    sections = [
        "# Generated validation tables",
        "",
        f"Generated by `scripts/make-validation-plots.py` on {platform.node()} ({os.cpu_count()} cores). Do not edit by hand.",
        "",
        "## Slab references (1e6 photons per case, seed 20261121)",
        "",
        slab_table(),
        "",
        "## Convergence, MCML classic case",
        "",
        convergence(),
        "",
        "## Rough glass sphere in a white furnace",
        "",
        rough_glass(),
        "",
    ]
    with open(os.path.join(GENERATED, "validation-tables.md"), "w") as f:
        f.write("\n".join(sections))
    print("wrote docs/generated/validation-tables.md and docs/images/slab_*.png")


if __name__ == "__main__":
    main()
