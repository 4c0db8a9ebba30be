"""study_report.py -- turn luxrad-study's CSV files into report.md and PNG
plots (gnuplot, pngcairo).  Usage: study_report.py OUTDIR [BUDGET_REPORT]
(budget.sh's report.md, made a section of this one).

The report's own figures (fig. 4.4, 4.7, 4.8; docs/ALGORITHM.md §9.3) are
printed beside ours; they are literature values, not measured here.
"""
import csv
import os
import subprocess
import sys

out = sys.argv[1]
rows = list(csv.DictReader(open(os.path.join(out, "iterations.csv"))))
summary = list(csv.DictReader(open(os.path.join(out, "summary.csv"))))
trade_path = os.path.join(out, "trade.csv")
trade = list(csv.DictReader(open(trade_path))) if os.path.exists(trade_path) else []
census_path = os.path.join(out, "census.csv")
census = (list(csv.DictReader(open(census_path)))
          if os.path.exists(census_path) else [])

REPORT = {  # scene: links classic, links new, MB classic, MB new, time
    "herd.glb": ("212,848", "209,433", "64.4", "56.0", "39m36s / 27m48s"),
    "hall-full.glb": ("1,100,641", "673,705", "95.0", "72.8", "2h58m / 2h14m"),
    "hall-bright.glb": ("387,624", "185,682", "25.5", "15.7", "13m08s / 16m41s"),
}

md = ["# Reduced-memory study: hr against rmb", ""]
md.append("Regenerate: `bash tests/bench/study.sh` (all figures below come "
          "from one run on one machine; times are wall clock and noisy).")
md.append("")
md.append("## Links, peak memory and time after %s iterations (same eps)"
          % (summary[0]["iterations"] if summary else "?"))
md.append("")
md.append("| scene | polygons | links hr | links rmb | ratio | peak hr MB | "
          "peak rmb MB | ratio | time hr s | time rmb s | ratio | grid RMS "
          "rmb vs hr | rmb-minimal links | rmb-minimal peak MB |")
md.append("|" + "---|" * 14)
for s in summary:
    mb = lambda b: "%.1f" % (int(b) / 1e6)
    md.append("| %s | %s | %s | %s | %.3f | %s | %s | %.3f | %.2f | %.2f | "
              "%.3f | %.2f %% | %s | %s |" % (
                  s["scene"], s["polygons"], s["links_hr"], s["links_rmb"],
                  float(s["links_ratio"]), mb(s["peak_hr"]), mb(s["peak_rmb"]),
                  float(s["peak_ratio"]), float(s["seconds_hr"]),
                  float(s["seconds_rmb"]), float(s["time_ratio"]),
                  100 * float(s["grid_rms_rel"]), s["links_rmb_minimal"],
                  mb(s["peak_rmb_minimal"])))
md.append("")
md.append("The report (1998, SGI; docs/ALGORITHM.md §9.3):")
md.append("")
md.append("| scene | links classic | links new | memory classic MB | "
          "memory new MB | time 4 it. classic / new |")
md.append("|---|---|---|---|---|---|")
for k, v in REPORT.items():
    md.append("| %s | %s |" % (k, " | ".join(v)))
md.append("")

KINDS = ("geometry", "bvh", "elements_surface", "elements_cluster", "links",
         "scratch")
md.append("## Memory by kind")
md.append("")
md.append("What each solver held with its scene, by structure, at the end "
          "of the iteration that held the most (MB; the engine's exact "
          "counts, without the `study` bookkeeping of re-created links "
          "that this study turns on: `other` is materials, lights, names "
          "and the rest), and the bytes per record that follow: surface "
          "elements, clusters (with the inner ones' records and the "
          "cluster order), links stored (with hr's list heads).  `peak` "
          "is the high-water mark, which a step passes between two ends "
          "of iterations.")
md.append("")
md.append("| scene | solver | iteration | " + " | ".join(KINDS) +
          " | other | total | peak | B/element | B/cluster | B/link |")
md.append("|" + "---|" * (len(KINDS) + 9))
work = lambda r: int(r["mem_total"]) - int(r["mem_study"])
per = lambda b, n: "%.1f" % (b / int(n)) if int(n) else "-"
for sc in sorted({r["scene"] for r in rows}):
    for v in ("hr", "rmb"):
        its = [r for r in rows if r["scene"] == sc and r["solver"] == v]
        if not its:
            continue
        r = max(its, key=work)
        kb = {k: int(r["mem_" + k]) for k in KINDS}
        total = work(r)
        md.append("| %s | %s | %s | %s | %.2f | %.2f | %.2f | %s | %s | %s |"
                  % (sc, v, r["iteration"],
                     " | ".join("%.2f" % (kb[k] / 1e6) for k in KINDS),
                     (total - sum(kb.values())) / 1e6, total / 1e6,
                     max(int(x["mem_peak_work"]) for x in its) / 1e6,
                     per(kb["elements_surface"], r["elements"]),
                     per(kb["elements_cluster"], r["clusters"]),
                     per(kb["links"], r["links"])))
md.append("")


def census_section(census, rows):
    """Where the elements sit, and what radiosity textures could save."""
    md.append("## Where the elements sit")
    md.append("")
    md.append("At the end of each solve (`census.csv`, `rad_census`): the "
              "surface elements, the share of them in polygons whose "
              "quadtree is complete to depth 2 or more (every element "
              "above that level split), the elements of levels 1 to d of "
              "those trees and the 4^d cells of a regular grid that could "
              "stand for them (a radiosity texture, report §5.2), with "
              "their bytes: the elements at this run's bytes per element, "
              "the grid at 36 bytes a cell (a leaf's B, I and dB) or 12 "
              "(B alone: the result).  Emitters: elements below the roots "
              "of polygons that only emit.")
    md.append("")
    md.append("| scene | solver | polygons | elements | per polygon | in "
              "trees complete to >= 2 | levels 1..d | cells | MB now | MB "
              "as grids (B, I, dB / B) | below emitters |")
    md.append("|" + "---|" * 11)
    for c in census:
        its = [r for r in rows if r["scene"] == c["scene"]
               and r["solver"] == c["solver"]]
        last = max(its, key=lambda r: int(r["iteration"])) if its else None
        bpe = (int(last["mem_elements_surface"]) / int(last["elements"])
               if last and int(last["elements"]) else float("nan"))
        n = int(c["elements"])
        deep = inner = cells = 0
        d = 2
        while "polys_d%d" % d in c:
            polys = int(c["polys_d%d" % d])
            deep += int(c["elements_d%d" % d])
            inner += polys * (4 ** (d + 1) - 4) // 3
            cells += polys * 4 ** d
            d += 1
        md.append("| %s | %s | %s | %d | %.2f | %.1f %% | %d | %d | %.2f | "
                  "%.2f / %.2f | %s |" % (
                      c["scene"], c["solver"], c["polygons"], n,
                      n / max(int(c["polygons"]), 1),
                      100.0 * deep / max(n, 1), inner, cells,
                      inner * bpe / 1e6, cells * 36 / 1e6, cells * 12 / 1e6,
                      c["below_emitters"]))
    md.append("")


if census:
    census_section(census, rows)

if len(sys.argv) > 2:  # the budget ladder, its headings one level down
    for line in open(sys.argv[2]).read().splitlines():
        md.append("#" + line if line.startswith("#") else line)
    md.append("")

if trade:
    md.append("## Speed / accuracy trade (converged to 1e-3)")
    md.append("")
    md.append("| scene | solver | eps | iterations | seconds | links | "
              "peak MB | grid error vs reference |")
    md.append("|---|---|---|---|---|---|---|---|")
    for t in trade:
        its = t["iterations"] + ("" if t["converged"] == "1" else " (cap)")
        md.append("| %s | %s | %s | %s | %.2f | %s | %.1f | %.2f %% |" % (
            t["scene"], t["solver"], t["eps"], its,
            float(t["seconds"]), t["links"], int(t["peak_bytes"]) / 1e6,
            100 * float(t["grid_rms_rel"])))
    md.append("")
    if any(t["converged"] != "1" for t in trade):
        md.append("Rows marked (cap) stopped at the iteration cap "
                  "(`luxrad-study --max-iterations`) before their error "
                  "estimate reached the tolerance: their error includes "
                  "energy not yet transported.  For progressive the eps "
                  "column names the rung; its knob is the mesh edge (0.1, "
                  "0.07, 0.05, 0.035, 0.025 of the scene diagonal), and a "
                  "finer mesh needs more shots, so at a fixed cap its "
                  "error grows down the ladder.")
        md.append("")


def series(scene, solver, col):
    return [(int(r["iteration"]), float(r[col])) for r in rows
            if r["scene"] == scene and r["solver"] == solver]


def plot(png, title, ylabel, curves, logy=True):
    """curves: list of (label, [(x, y)...])."""
    dat = os.path.join(out, png + ".dat")
    with open(dat, "w") as f:
        for label, pts in curves:
            f.write("# %s\n" % label)
            for x, y in pts:
                f.write("%g %g\n" % (x, y))
            f.write("\n\n")
    cmds = ["set terminal pngcairo size 900,560",
            "set output '%s'" % os.path.join(out, png + ".png"),
            "set title '%s'" % title, "set xlabel 'iteration'",
            "set ylabel '%s'" % ylabel, "set key outside right",
            "set grid"]
    if logy:
        cmds.append("set logscale y")
    plots = ["'%s' index %d with linespoints title '%s'" % (dat, i, label)
             for i, (label, _) in enumerate(curves)]
    cmds.append("plot " + ", ".join(plots))
    subprocess.run(["gnuplot"], input="\n".join(cmds), text=True, check=True)
    os.remove(dat)
    md.append("![%s](%s.png)" % (title, png))
    md.append("")


scenes = sorted({r["scene"] for r in rows})
md.append("## Figures")
md.append("")
plot("fig3_5_links", "Links stored per iteration (fig. 3.5, 4.4)", "links",
     [("%s %s" % (s, v), series(s, v, "links")) for s in scenes
      for v in ("hr", "rmb")])
plot("fig3_7_useful", "hr: useful vs created links (fig. 3.7)", "links",
     [("%s %s" % (s, c), series(s, "hr", "links_" + c)) for s in scenes
      for c in ("created", "useful")])
per_elem = lambda s, v: [(x, l / max(e, 1)) for (x, l), (_, e) in
                         zip(series(s, v, "links"), series(s, v, "elements"))]
plot("fig3_8_links_per_element", "Links per element (fig. 3.8)",
     "links / element", [("%s %s" % (s, v), per_elem(s, v)) for s in scenes
                         for v in ("hr", "rmb")])
plot("fig3_9_leaves", "Leaves per iteration (fig. 3.9)", "leaves",
     [("%s %s" % (s, v), series(s, v, "leaves")) for s in scenes
      for v in ("hr", "rmb")])
plot("fig4_3_rmb_stored_useful", "rmb: stored vs useful links (fig. 4.3)",
     "links", [("%s %s" % (s, c), series(s, "rmb", c)) for s in scenes
               for c in ("links", "links_active", "links_useful")])
plot("fig4_7_memory", "Memory (peak so far) classic vs new (fig. 4.7)",
     "bytes", [("%s %s" % (s, v), series(s, v, "mem_peak_work"))
               for s in scenes for v in ("hr", "rmb")])
plot("fig4_9_recreated", "rmb: links re-created per iteration (fig. 4.9)",
     "links", [(s, [(x, max(y, 0.5)) for x, y in
                    series(s, "rmb", "links_recreated")]) for s in scenes])

with open(os.path.join(out, "report.md"), "w") as f:
    f.write("\n".join(md) + "\n")
print("\n".join(md[:40]))
