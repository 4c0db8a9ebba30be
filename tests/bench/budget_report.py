#!/usr/bin/env python3
"""budget_report.py OUT REF SCENES FRAC... -- the memory-budget ladder.
budget_report.py --solver-peak JSON -- a solve's own peak, MiB.

Reads what tests/bench/budget.sh left in OUT (runs/NAME.SOLVER.TAG.{json,
time,rc,err,budget}, TAG "none" or a fraction of the unconstrained
solver's peak) and the validation study's references in REF (ref/NAME.json,
as validate_report.py reads them).  Writes OUT/runs.csv and OUT/report.md:
per scene and solver, each budget with its status, the solver's own peak,
wall time, worst and mean error against the reference, links stored and
the pairs the budget held at a coarser level (last iteration).
"""
import csv
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import validate_report as vr  # noqa: E402


def solver_peak_mib(path):
    """The solver's own peak in a luxrad-solve --json (MiB): what
    memory_budget bounds."""
    o = vr.load_json(path)
    if o is None or "stats" not in o:
        return float("nan")
    return o["stats"]["memory"]["peak_own_bytes"] / 1048576.0


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "--solver-peak":
        print(solver_peak_mib(sys.argv[2]))
        return
    out, refdir, table = sys.argv[1], sys.argv[2], sys.argv[3]
    tags = ["none"] + sys.argv[4:]
    rows = []
    for line in table.splitlines():
        if not line.strip():
            continue
        name, _scene, points, ref = line.split("|")
        npts = vr.count_points(points)
        refv, sd, _note = vr.reference(refdir, name, ref, npts)
        for solver in vr.SOLVERS:
            base_err = None
            for tag in tags:
                run = vr.one_run(out, name, solver, tag, refv, sd)
                if run is None:
                    continue
                base = os.path.join(out, "runs",
                                    "%s.%s.%s" % (name, solver, tag))
                run["budget_mib"] = float(vr.read_text(base + ".budget")
                                          or 0)
                run["solver_peak_mib"] = solver_peak_mib(base + ".json")
                o = vr.load_json(base + ".json") or {}
                st = o.get("stats", {})
                run["budget_held"] = st.get("links", {}).get("budget_held")
                run["budget_reached"] = st.get("budget_reached")
                run["restarts"] = st.get("budget_restarts", 0)
                run["eps"] = st.get("eps")
                its = o.get("per_iteration", [])
                run["study"] = bool(o.get("options", {}).get("study"))
                for key in ("transient", "recreated", "budget_transient"):
                    run[key] = sum(it.get("links", {}).get(key, 0)
                                   for it in its)
                run["tag"] = tag
                if tag == "none" and "mean" in run:
                    base_err = run["mean"]
                run["mean_ratio"] = (run["mean"] / base_err
                                     if base_err and "mean" in run
                                     else float("nan"))
                rows.append(run)
    cols = ["scene", "solver", "tag", "budget_mib", "status",
            "solver_peak_mib", "wall_s", "iterations", "links", "worst",
            "mean", "mean_ratio", "budget_held", "budget_reached",
            "restarts", "eps",
            "transient", "recreated", "budget_transient"]
    with open(os.path.join(out, "runs.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for r in rows:
            w.writerow([r.get(c, "") for c in cols])
    md = ["# Memory-budget ladder", "",
          "Budget: a fraction of the solver's own peak with no budget "
          "(scene polygons and BVH left out).  Error against the "
          "validation study's references; mean x is the mean error over "
          "the unbudgeted run's.  Transient: links gathered without being "
          "stored, over all iterations (rmb), of which made so by the "
          "budget; re-created: links stored again after an earlier "
          "iteration deleted their pair (with budget.sh --study); "
          "restarts: hr started over at twice eps, the budget reached in "
          "its first two iterations (eps: the one it went on with).", "",
          "| scene | solver | budget | MiB | status | solver peak MiB | "
          "wall s | links | worst | mean | mean x | held (last it.) | "
          "transient (budget) | re-created | restarts (eps) |",
          "|---|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"
          "---:|---:|"]
    for r in rows:
        ok = r["status"] == "ok"
        md.append("| %s | %s | %s | %.1f | %s | %.1f | %.2f | %s | %s | "
                  "%s | %s | %s | %s | %s | %s |" % (
                      r["scene"], r["solver"],
                      "none" if r["tag"] == "none"
                      else "%d %%" % round(100 * float(r["tag"])),
                      r["budget_mib"], r["status"][:70],
                      r["solver_peak_mib"], r["wall_s"],
                      r.get("links", "") if ok else "",
                      vr.pct(r["worst"]) if "worst" in r else "",
                      "%.2f %%" % (100 * r["mean"]) if "mean" in r else "",
                      "%.2f" % r["mean_ratio"] if "mean" in r else "",
                      r.get("budget_held", "") if ok else "",
                      "%d (%d)" % (r["transient"], r["budget_transient"])
                      if ok else "",
                      r["recreated"] if ok and r["study"] else "",
                      "%d (%g)" % (r["restarts"], r["eps"])
                      if ok and r.get("restarts") else ""))
    with open(os.path.join(out, "report.md"), "w") as f:
        f.write("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
