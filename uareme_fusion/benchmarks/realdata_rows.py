"""The rows of `bench realdata`: each figure beside its goal and verdict (`figure_rows`), and the compact
results file of `--markdown` (`markdown`). The figures come from `benchmarks.realdata`."""

from __future__ import annotations

import numpy as np

JOINT = "RGB normals+lines"
"""The cue set of the joint solve (a key of `realdata.CUE_SETS`), judged against the better single cue."""
NEES_RANGE = (1.0, 6.0)
STD_SEPARATION_GOAL = 0.5
NO_INFORMATION_SHARE = 0.9
"""A cue set whose frames claim no information (`realdata.claims_no_information`: the covariance at the cap, a
reason given) on at least this share of the frames has its NEES and std separation printed, not judged: a std
of 57 deg per axis says nothing is known, and a NEES below 1 is then what it should be (real TUM and EuRoC, lines
alone: the segments fit no better than chance on every frame)."""


NO_WORSE_TOLERANCE_DEG = 0.005
"""A paired interval lying above 0 by less than this (deg, half the tables' 0.01) is float noise, not worse:
real TUM eval, the joint solve against normals alone (the lines took no share), 7.32 against 7.32 deg,
+0.00 (+0.00 .. +0.00) read FAIL."""


def no_worse(interval: dict) -> bool | None:
    """A paired difference (A - B, deg) whose 95 % interval does not lie wholly above 0 (beyond
    `NO_WORSE_TOLERANCE_DEG`): A is no worse than B beyond the interval. None without frames."""
    return None if not interval.get("frames") else bool(interval["low"] <= NO_WORSE_TOLERANCE_DEG)


def _interval(d: dict | None) -> str:
    if not d or not d.get("frames"):
        return ""
    return f"{d['mean']:+.2f} ({d['low']:+.2f} .. {d['high']:+.2f})"


def _verdict(ok: bool | None) -> str:
    return "" if ok is None else ("ok" if ok else "FAIL")


def _in_nees(value: float) -> bool | None:
    return None if not np.isfinite(value) else bool(NEES_RANGE[0] <= value <= NEES_RANGE[1])


def _row(seq: str, figure: str, measured: str, goal: str = "", versus: str = "", interval: str = "",
         ok: bool | None = None) -> dict:
    return {"sequence": seq, "figure": figure, "measured": measured, "goal": goal, "versus": versus,
            "paired_95": interval, "verdict": _verdict(ok)}


def figure_rows(name: str, fig: dict) -> list[dict]:
    """The printed rows of one sequence's figures."""
    rows, cues = [], fig["cue_sets"]
    depth = cues.get("depth", {})
    depth_are = depth.get("single", {}).get("are_mean_deg")
    tum = name.startswith("TUM")
    for cue, backends in cues.items():
        single = backends["single"]
        no_info = single.get("no_information_fraction", 0.0)
        judged = not no_info >= NO_INFORMATION_SHARE
        unjudged = f"not judged: {100 * no_info:.0f} % of the frames claim no information (the cap)"
        for backend, row in backends.items():
            kind = row.get("nees_kind")
            figure = f"{cue}, {backend}: ARE / NEES" + (f" ({kind})" if kind else "") + (
                " / tilt" if "tilt_mean_deg" in row else "")
            measured = f"{row['are_mean_deg']:.2f} / {row['nees_mean']:.2f}" + (
                f" / {row['tilt_mean_deg']:.2f}" if "tilt_mean_deg" in row else "")
            goal, versus, interval, ok = f"NEES in [{NEES_RANGE[0]:g}, {NEES_RANGE[1]:g}]", "", "", _in_nees(row["nees_mean"])
            if not judged:
                goal, ok = f"NEES {unjudged}", (None if backend == "single" else True)
            if backend == "single" and tum and cue.startswith("RGB") and cue == JOINT:
                limit = min(8.0, 1.5 * depth_are) if depth_are is not None else 8.0
                goal = f"ARE <= 8 and <= 1.5x depth ({limit:.2f}); " + goal
                ok = ok and row["are_mean_deg"] <= limit
            if backend == "single" and tum and cue == "depth":
                goal = "ARE <= 4, NEES <= 6; NEES >= 1"
                ok = row["are_mean_deg"] <= 4.0 and ok
            if backend != "single" and tum and cue == JOINT and backend in depth:
                limit = min(8.0, 1.5 * depth[backend]["are_mean_deg"])  # the same backend on depth normals
                goal = f"ARE <= 8 and <= 1.5x depth's {backend} ({limit:.2f}); " + goal
                ok = ok and row["are_mean_deg"] <= limit
            if backend != "single":
                goal = f"ARE no worse than single ({single['are_mean_deg']:.2f}); " + goal
                interval = _interval(row["are_vs_single_deg"])
                versus = "vs single"
                ok = no_worse(row["are_vs_single_deg"]) and ok
            rows.append(_row(name, figure, measured, goal, versus, interval, ok))
            if "tilt_vs_imu_deg" in row and backend != "single":
                d = row["tilt_vs_imu_deg"]
                rows.append(_row(name, f"{cue}, {backend}: tilt vs the IMU alone (same frames)",
                                 f"{row['tilt_mean_deg']:.2f} vs {row['tilt_mean_deg'] - d['mean']:.2f}",
                                 "tilt no worse than the IMU's", "vs IMU alone", _interval(d), no_worse(d)))
        if "best_single_cue" in single:
            best = single["best_single_cue"]
            rows.append(_row(name, f"{cue} joint vs the better single cue ({best}, single)",
                             f"{single['are_mean_deg']:.2f} vs {cues[best]['single']['are_mean_deg']:.2f}",
                             "no worse beyond the paired 95 % interval", f"vs {best}",
                             _interval(single["are_vs_best_single_cue_deg"]),
                             no_worse(single["are_vs_best_single_cue_deg"])))
        sep = single["std_separation"]
        oracle = sep.get("oracle_ratio", float("nan"))
        rows.append(_row(name, f"{cue}, single: std separation, median ARE of the low-std / high-std half",
                         f"{sep['low_std_median']:.2f} / {sep['high_std_median']:.2f} (ratio {sep['ratio']:.2f})",
                         f"ratio <= {STD_SEPARATION_GOAL}" if judged else unjudged,
                         f"oracle (ranked by the true error) {oracle:.2f}"
                         + (": the goal is out of reach" if oracle > STD_SEPARATION_GOAL else ""), "",
                         None if not (judged and np.isfinite(sep["ratio"])) else sep["ratio"] <= STD_SEPARATION_GOAL))
    if "eval_default" in fig:
        e = fig["eval_default"]
        rows.append(_row(name, f"eval, default options ({e['normals']} / {e['backend']}): ARE / NEES",
                         f"{e['are_mean_deg']:.2f} / {e['nees_mean']:.2f}", "ARE <= 0.5", "", "",
                         e["are_mean_deg"] <= 0.5))
    if "eval_with_imu" in fig:
        e = fig["eval_with_imu"]
        d = e["fused_vs_imu_tilt_deg"]
        rows.append(_row(name, f"eval, default options ({e['normals']} / {e['backend']}): fused tilt / NEES",
                         f"{e['fused_tilt_mean_deg']:.2f} / {e['fused_nees_mean']:.2f}",
                         f"tilt <= 1.0 and <= IMU; NEES in [{NEES_RANGE[0]:g}, {NEES_RANGE[1]:g}]",
                         f"IMU alone {e['imu_tilt_same_frames_mean_deg']:.2f} (same {e['frames']} frames; "
                         f"whole log {e['imu_tilt_whole_log_mean_deg']:.2f})", _interval(d),
                         e["fused_tilt_mean_deg"] <= 1.0 and bool(no_worse(d)) and bool(_in_nees(e["fused_nees_mean"]))))
    for a in fig.get("accelerometer", {}).values():
        w = a["without"]
        rows.append(_row(name, f"eval --no-accel ({w['normals']} / {w['backend']}): tilt / ARE / NEES",
                         f"{w['tilt_mean_deg']:.2f} / {w['are_mean_deg']:.2f} / {w['nees_mean']:.2f}",
                         "", "tilt after the alignment" if "alignment" in w["tilt_note"] else ""))
        if "note" in a["with"]:
            rows.append(_row(name, "eval with the Kinect accelerometer", a["with"]["note"], "tilt <= without"))
            continue
        v = a["with"]
        d = v["tilt_vs_without_deg"]
        rows.append(_row(name, f"eval with the Kinect accelerometer ({v['normals']} / {v['backend']}): "
                         "tilt / ARE / NEES", f"{v['tilt_mean_deg']:.2f} / {v['are_mean_deg']:.2f} / "
                         f"{v['nees_mean']:.2f}", "tilt no worse than --no-accel", "vs --no-accel", _interval(d),
                         no_worse(d)))
        rows.append(_row(name, f"eval with the Kinect accelerometer ({v['normals']}): ARE vs --no-accel",
                         f"{v['are_mean_deg']:.2f} vs {w['are_mean_deg']:.2f}", "", "vs --no-accel",
                         _interval(v["are_vs_without_deg"])))
    return rows


COLUMNS = (("sequence", "sequence"), ("figure", "figure"), ("measured", "measured"), ("goal", "goal"),
           ("versus", "against"), ("paired_95", "A - B, paired 95 %"), ("verdict", ""))


def markdown(results: dict) -> str:
    """The compact results file of `--markdown`: one table of every row, then the skipped sequences."""
    lines = ["# bench realdata" + (" (--quick)" if results["quick"] else ""), "",
             "Angles in degrees; ARE after one constant alignment; paired 95 % intervals are of the per-frame "
             "difference A - B (moving-block bootstrap).", "",
             "| " + " | ".join(title or "verdict" for _, title in COLUMNS) + " |",
             "|" + "---|" * len(COLUMNS)]
    for row in results["rows"]:
        lines.append("| " + " | ".join(row[key].replace("|", "/") for key, _ in COLUMNS) + " |")
    lines += [""] + [f"- {line}" for line in results["skipped"]]
    return "\n".join(lines) + "\n"
