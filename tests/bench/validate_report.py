#!/usr/bin/env python3
"""validate_report.py OUT SCENES -- the validation study's report.

Reads what tests/bench/validate.sh left in OUT (ref/NAME.json from
luxrad-reference, runs/NAME.SOLVER.ACC.{json,time,rc,err}) and SCENES (the
script's table, one 'name|scene|points|reference' per line).  Writes
OUT/runs.csv (one row per solve), OUT/points.csv (one row per point and
solve), OUT/report.md and, with gnuplot, OUT/NAME.png per scene: worst and
mean error against wall time and against peak memory, the reference's
error bar as a dashed line.

Error of a point: (lux - reference) / reference.  A point is covered
when |lux - reference| <= error_lux + 3 reference standard errors.  A run
is on the Pareto front of its scene when no other run of that scene is
both faster (wall time) and more accurate (worst error).
"""
import csv
import json
import math
import os
import re
import subprocess
import sys

ACCS = ["default", "0.01", "0.005"]
SOLVERS = ["hr", "rmb"]


def load_json(path):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def read_text(path):
    try:
        with open(path) as f:
            return f.read().strip()
    except OSError:
        return ""


def reference(out, name, ref, npts):
    """(values, standard errors, note) or (None, None, why)."""
    if ref.startswith("exact:"):
        v = float(ref[6:])
        return [v] * npts, [0.0] * npts, "exact"
    r = load_json(os.path.join(out, "ref", name + ".json"))
    if r is None:
        err = read_text(os.path.join(out, "ref", name + ".err"))
        return None, None, err.splitlines()[-1] if err else "no reference"
    return r["illuminance_lux"], r["stderr_lux"], "luxrad-reference"


def count_points(path):
    n = 0
    with open(path) as f:
        for line in f:
            line = line.split("#", 1)[0].strip()
            if line:
                n += 1
    return n


def read_points(path):
    pts = []
    with open(path) as f:
        for line in f:
            line = line.split("#", 1)[0].split()
            if line:
                pts.append([float(x) for x in line[:3]])
    return pts


def lux_errors(lux, ref):
    """(errors, worst, mean) of lux against ref: per point
    (lux - ref) / ref, NaN where ref lights nothing; the signed error
    furthest from 0 (NaN without a lit point) and the mean of |error|
    (0 without one), over the lit points."""
    errs = [(a - r) / r if r > 0 else float("nan") for a, r in zip(lux, ref)]
    good = [e for e in errs if not math.isnan(e)]
    worst = max(good, key=abs) if good else float("nan")
    mean = sum(abs(e) for e in good) / len(good) if good else 0
    return errs, worst, mean


def one_run(out, name, solver, acc, ref, sd):
    base = os.path.join(out, "runs", "%s.%s.%s" % (name, solver, acc))
    if not os.path.exists(base + ".rc"):
        return None
    rc = read_text(base + ".rc")
    run = {"scene": name, "solver": solver, "accuracy": acc}
    t = read_text(base + ".time").split()
    try:
        run["wall_s"] = float(t[-2])
        run["peak_rss_mb"] = float(t[-1]) / 1024
    except (IndexError, ValueError):
        run["wall_s"] = run["peak_rss_mb"] = float("nan")
    o = load_json(base + ".json")
    if rc != "0" or o is None:
        msg = read_text(base + ".err").splitlines()
        why = msg[-1] if msg else "failed (exit %s)" % rc
        # "luxrad-solve: PATH: message": the message is what matters.
        why = re.sub(r"^[\w-]+: .*?\.(gltf|glb): ", "", why)
        run["status"] = "timeout" if rc == "124" else why
        return run
    if "stats" not in o:  # written before luxrad-solve's JSON had stats
        run["status"] = "stale run: rerun validate.sh"
        return run
    lux, el = o["illuminance_lux"], o["error_lux"]
    st = o["stats"]
    run.update(status="ok", iterations=st["iteration"],
               links=st["links"]["stored"], converged=o["converged"],
               engine_peak_mb=st["memory"]["peak_bytes"] / 1e6,
               solve_s=o["seconds"], query_s=o["query_seconds"],
               lux=lux, error_lux=el)
    if ref is None:
        run["status"] = "ok (no reference)"
        return run
    run["errs"], run["worst"], run["mean"] = lux_errors(lux, ref)
    run["covered"] = sum(1 for a, r, u, s in zip(lux, ref, el, sd)
                         if abs(a - r) <= u + 3 * s)
    return run


def pareto(runs):
    ok = [r for r in runs if "worst" in r]
    for r in ok:
        r["pareto"] = not any(
            o is not r and o["wall_s"] <= r["wall_s"] and
            abs(o["worst"]) <= abs(r["worst"]) and
            (o["wall_s"] < r["wall_s"] or abs(o["worst"]) < abs(r["worst"]))
            for o in ok)


def pct(x):
    return "%+.2f %%" % (100 * x) if not math.isnan(x) else "-"


def gnuplot(out, script, what):
    """Run a gnuplot script in out; False (and a message) if it failed."""
    try:
        subprocess.run(["gnuplot"], input=script, text=True, cwd=out,
                       check=True, capture_output=True)
    except (OSError, subprocess.CalledProcessError) as e:
        print("validate_report: %s: gnuplot: %s" % (what, e), file=sys.stderr)
        return False
    return True


def plot(out, name, runs, ref_rel):
    ok = [r for r in runs if "worst" in r]
    if not ok:
        return None
    dat = os.path.join(out, name + ".dat")
    with open(dat, "w") as f:
        for s in SOLVERS:
            f.write("# %s\n" % s)
            for r in ok:
                if r["solver"] == s:
                    f.write("%g %g %g %g %s\n" % (
                        r["wall_s"], 100 * abs(r["worst"]), 100 * r["mean"],
                        r["peak_rss_mb"], r["accuracy"]))
            f.write("\n\n")
    png = name + ".png"
    script = """
set terminal pngcairo size 1000,420 font ",10"
set output '%(png)s'
set multiplot layout 1,2 title '%(name)s: error against luxrad-reference or the closed form'
set logscale x
set ylabel 'error, %% (worst: filled, mean: open)'
set key top right
set grid
set xlabel 'wall time, s'
plot %(ref)s \\
  '%(dat)s' index 0 using 1:2 with points pt 7 ps 1.3 lc 1 title 'hr worst', \\
  '' index 0 using 1:3 with points pt 6 ps 1.3 lc 1 title 'hr mean', \\
  '' index 1 using 1:2 with points pt 5 ps 1.3 lc 2 title 'rmb worst', \\
  '' index 1 using 1:3 with points pt 4 ps 1.3 lc 2 title 'rmb mean', \\
  '' index 0 using 1:2:5 with labels offset 1,0.6 font ',8' notitle, \\
  '' index 1 using 1:2:5 with labels offset 1,0.6 font ',8' notitle
set xlabel 'peak memory (RSS), MB'
plot %(ref)s \\
  '%(dat)s' index 0 using 4:2 with points pt 7 ps 1.3 lc 1 title 'hr worst', \\
  '' index 0 using 4:3 with points pt 6 ps 1.3 lc 1 title 'hr mean', \\
  '' index 1 using 4:2 with points pt 5 ps 1.3 lc 2 title 'rmb worst', \\
  '' index 1 using 4:3 with points pt 4 ps 1.3 lc 2 title 'rmb mean'
unset multiplot
""" % {"png": png, "name": name, "dat": os.path.basename(dat),
       "ref": ("%g with lines dt 2 lc 8 title 'reference, 3 s.e.'," %
               (300 * ref_rel)) if ref_rel > 0 else ""}
    return png if gnuplot(out, script, name) else None


def summary(out, md, runs, names):
    """A table of every scene at a glance, inserted after the intro, and
    summary.png: |worst error| per scene, hr and rmb, default and 0.01."""
    by = {(r["scene"], r["solver"], r["accuracy"]): r for r in runs}

    def cell(r, full):
        if r is None:
            return "-"
        if "worst" not in r:
            return r["status"].replace("|", "/")[:60]
        wm = "%s (%.1f %%)" % (pct(r["worst"]), 100 * r["mean"])
        if not full:
            return wm
        return "%s, %.1f s, %.0f MB" % (wm, r["wall_s"], r["peak_rss_mb"])
    rows = ["## Summary", "",
            "Worst error over each scene's points (signed) and, in "
            "brackets, the mean of |error|; wall time and peak memory at "
            "the defaults.", "",
            "| scene | hr, defaults | rmb, defaults | hr, 0.01 | rmb, 0.01 "
            "| hr, 0.005 | rmb, 0.005 |",
            "|---|---|---|---|---|---|---|"]
    dat = os.path.join(out, "summary.dat")
    keys = (("hr", "default"), ("rmb", "default"), ("hr", "0.01"),
            ("rmb", "0.01"))
    has = [False] * len(keys)
    with open(dat, "w") as f:
        for n in names:
            if not any(k[0] == n for k in by):
                continue
            rows.append("| %s | %s | %s | %s | %s | %s | %s |" % (
                n, cell(by.get((n, "hr", "default")), True),
                cell(by.get((n, "rmb", "default")), True),
                cell(by.get((n, "hr", "0.01")), False),
                cell(by.get((n, "rmb", "0.01")), False),
                cell(by.get((n, "hr", "0.005")), False),
                cell(by.get((n, "rmb", "0.005")), False)))
            v = []
            for i, key in enumerate(keys):
                r = by.get((n,) + key)
                ok = r is not None and "worst" in r
                has[i] = has[i] or ok
                v.append("%g" % (100 * abs(r["worst"])) if ok else "NaN")
            f.write("%s %s\n" % (n, " ".join(v)))
    rows += ["", "![summary](summary.png)", ""]
    md[4:4] = rows
    titles = ["hr, defaults", "rmb, defaults", "hr, --accuracy 0.01",
              "rmb, --accuracy 0.01"]
    series = ["'summary.dat' using %d%s title '%s'" %
              (i + 2, ":xtic(1)" if not any(has[:i]) else "", titles[i])
              for i in range(len(keys)) if has[i]]
    if not series:
        return
    script = """
set terminal pngcairo size 1100,420 font ",10"
set output 'summary.png'
set title '|worst error| per scene against luxrad-reference or the closed form'
set style data histogram
set style histogram clustered gap 1
set style fill solid 0.8 border -1
set ylabel '%%'
set logscale y
set yrange [0.1:300]
set grid y
set xtics rotate by -30
set key top left
plot %s, 2 with lines dt 2 lc 8 title 'target, defaults (2 %%)'
""" % ", ".join(series)
    gnuplot(out, script, "summary")


AUDIT_CLASSES = ["s <- s", "s <- c", "c <- s", "c <- c", "s <- s near",
                 "s <- c near", "c <- s near", "c <- c near"]


def audit_table(out, names):
    """The link audit of each scene's hr solve at the defaults (its
    runs/NAME.audit.json): per class, what the links move over what Monte
    Carlo says they should, with the class's share of the Monte Carlo
    transfer in brackets; *all* is the ratio over every audited link."""
    md = ["## Link audit (hr, defaults)", "",
          "`luxrad-solve SCENE --audit-links 10`: one link in 10 held to "
          "Monte Carlo (64 point pairs and shadow rays each).  Per class "
          "(s: surface, c: cluster, receiver <- source; near: the larger "
          "end is larger than the distance between the centres), what the "
          "links move over what they should move (A F B, by Monte Carlo "
          "with each sample's own radiosity), and in brackets the class's "
          "share of that transfer.  Below 1 the solve loses light there, "
          "above 1 it makes some.", "",
          "| scene | " + " | ".join(AUDIT_CLASSES) + " | all |",
          "|---" * (len(AUDIT_CLASSES) + 2) + "|"]
    rows = 0
    for name in names:
        j = load_json(os.path.join(out, "runs", name + ".audit.json"))
        if not j or "audit" not in j:
            continue
        cls = j["audit"]["classes"]
        total = sum(c["mc_transfer"] for c in cls)
        cells, moved, should = [], 0.0, 0.0
        for c in cls:
            if c["links"] == 0 or c["mc_transfer"] <= 0 or total <= 0:
                cells.append("–")
                continue
            moved += c["stored_transfer"]
            should += c["mc_transfer"]
            cells.append("%.2f (%.0f %%)" % (
                c["stored_transfer"] / c["mc_transfer"],
                100 * c["mc_transfer"] / total))
        md.append("| %s | %s | %s |" % (
            name, " | ".join(cells),
            "%.3f" % (moved / should) if should > 0 else "–"))
        rows += 1
    return md + [""] if rows else []


def main():
    out, table = sys.argv[1], sys.argv[2]
    scenes = [l.split("|") for l in table.splitlines() if l.strip()]
    allruns = []
    md = ["# Validation study", "",
          "Every scene solved by hr and rmb at the default accuracy and with "
          "`--accuracy 0.01` and `0.005`, its points compared with "
          "luxrad-reference (independent Monte Carlo, 0.2 % standard error "
          "per point) or with the exact value of the closed boxes.  Error = "
          "(lux - reference) / reference; *worst* is the point furthest off "
          "(signed), *mean* the mean of |error|; *covered*: points whose "
          "`error_lux` plus 3 reference standard errors holds the "
          "difference.  Wall time and peak memory (RSS) of the whole "
          "`luxrad-solve` run (load, solve, query).  Runs marked * are on "
          "their scene's Pareto front (no other run both faster and more "
          "accurate).  Made by `bash tests/bench/validate.sh`.", ""]
    pts_rows = []
    for name, scene, points, ref in scenes:
        if not os.path.exists(points):
            continue
        npts = count_points(points)
        rv, sd, note = reference(out, name, ref, npts)
        runs = []
        for s in SOLVERS:
            for a in ACCS:
                r = one_run(out, name, s, a, rv, sd or [0] * npts)
                if r:
                    runs.append(r)
        if not runs:
            continue
        pareto(runs)
        rel = 0.0
        if rv is not None:
            rels = [s_ / v for v, s_ in zip(rv, sd) if v > 0]
            rel = sum(rels) / len(rels) if rels else 0
        coords = read_points(points)
        md += ["## %s" % name, "",
               "Reference: %s%s." % (note, ", mean standard error %.2f %%" %
                                     (100 * rel) if rel > 0 else ""), "",
               "| solver | accuracy | worst | mean | covered | wall time | "
               "peak RSS | links | iterations |",
               "|---|---|---|---|---|---|---|---|---|"]
        for r in runs:
            allruns.append(r)
            if r["status"].startswith("ok") and "worst" in r:
                md.append("| %s | %s | %s | %.2f %% | %d/%d | %.2f s%s | "
                          "%.0f MB | %s | %s |" % (
                              r["solver"], r["accuracy"],
                              pct(r["worst"]), 100 * r["mean"], r["covered"],
                              npts, r["wall_s"],
                              " *" if r.get("pareto") else "",
                              r["peak_rss_mb"], r["links"],
                              r["iterations"]))
                for i, (p, e) in enumerate(zip(coords, r["errs"])):
                    pts_rows.append([name, r["solver"], r["accuracy"], i] +
                                    p + [rv[i], sd[i], r["lux"][i],
                                         r["error_lux"][i], 100 * e])
            else:
                md.append("| %s | %s | %s | | | %.2f s | | | |" % (
                    r["solver"], r["accuracy"],
                    r["status"].replace("|", "/")[:120],
                    r.get("wall_s", float("nan"))))
        md.append("")
        r_png = plot(out, name, runs, rel)
        if r_png:
            md += ["![%s](%s)" % (name, r_png), ""]
    summary(out, md, allruns, [sc[0] for sc in scenes])
    md += audit_table(out, [sc[0] for sc in scenes])
    with open(os.path.join(out, "runs.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "solver", "accuracy", "status", "worst_pct",
                    "mean_pct", "covered", "wall_s", "peak_rss_mb",
                    "engine_peak_mb", "solve_s", "query_s", "links",
                    "iterations", "converged", "pareto"])
        for r in allruns:
            w.writerow([r["scene"], r["solver"], r["accuracy"], r["status"],
                        "%.3f" % (100 * r["worst"]) if "worst" in r else "",
                        "%.3f" % (100 * r["mean"]) if "mean" in r else "",
                        r.get("covered", ""), "%.3f" % r["wall_s"],
                        "%.1f" % r["peak_rss_mb"],
                        "%.1f" % r["engine_peak_mb"]
                        if "engine_peak_mb" in r else "",
                        "%.3f" % r["solve_s"] if "solve_s" in r else "",
                        "%.3f" % r["query_s"] if "query_s" in r else "",
                        r.get("links", ""), r.get("iterations", ""),
                        r.get("converged", ""), int(r.get("pareto", False))])
    with open(os.path.join(out, "points.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "solver", "accuracy", "point", "x", "y", "z",
                    "reference_lux", "reference_stderr_lux", "lux",
                    "error_lux", "error_pct"])
        w.writerows(pts_rows)
    with open(os.path.join(out, "report.md"), "w") as f:
        f.write("\n".join(md) + "\n")


if __name__ == "__main__":
    main()
