"""ECD and horizon_uav photos turned by 90, 180 and 270 deg through `image` (issue 26): per photo and turn
the verdict (right, declined or confidently wrong, `benchmarks/turned.py`) and what decided it, one JSON
line each; a summary per set, turn and ECD half (odd: tuning, even: held out) at the end.

Usage: python tools/turned_photos.py [--data ../shared/data] [--sets ecd,uav] [--quarters 0,1,2,3]
       [--stride N] [--out FILE.jsonl] [--only EARLIER.jsonl]
Measured (REAL, ECD, right / declined / confidently wrong of 309 turned answers): 0 / 206 / 103 before the
sky-up turn (pipeline/turned_photo.py), 30 / 173 / 106 after (the 3 new: ECD 032, as wrong upright).
"""

from __future__ import annotations

import argparse
import collections
import csv
import json
import sys
from pathlib import Path

import cv2
import scipy.io

from uareme_fusion.benchmarks.horizon_uav import label_line
from uareme_fusion.benchmarks.turned import sky_side_up, turned_line, verdict
from uareme_fusion.pipeline.turned_photo import turned_photo
from uareme_fusion.pipeline.single_image import ImageAnalyser


def photos(data: Path, name: str, stride: int):
    """(set, stem, half, rgb, upright labelled horizon positive on the sky side)."""
    if name == "ecd":
        for path in sorted((data / "eurasian_cities").glob("*.jpg"))[::stride]:
            rgb = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
            truth = sky_side_up(scipy.io.loadmat(path.with_name(path.stem + "hor.mat"))["horizon"].ravel())
            yield "ecd", path.stem, "odd" if int(path.stem) % 2 else "even", rgb, truth
    else:
        folder = data / "horizon_uav"
        for row in list(csv.DictReader((folder / "label.csv").open()))[::stride]:
            rgb = cv2.cvtColor(cv2.imread(str(folder / "images" / row["filename"])), cv2.COLOR_BGR2RGB)
            yield "uav", row["filename"], "all", rgb, label_line(float(row["slope"]), float(row["offset"]), rgb.shape[0])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("../shared/data"))
    ap.add_argument("--sets", default="ecd,uav")
    ap.add_argument("--quarters", default="0,1,2,3")
    ap.add_argument("--stride", type=int, default=1)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--only", type=Path, help="a JSON-lines output: analyse only its (photo, turn) rows whose "
                    "horizon was in doubt (doubt_deg > 0)")
    args = ap.parse_args(argv)
    analyser = ImageAnalyser()
    quarters = [int(q) for q in args.quarters.split(",")]
    out = args.out.open("w") if args.out else None
    counts = collections.Counter()
    only = None
    if args.only:
        only = {(r["photo"], r["quarters"]) for r in map(json.loads, args.only.open()) if r["doubt_deg"] > 0}
    for name in args.sets.split(","):
        for set_name, stem, half, rgb, truth in photos(args.data, name, args.stride):
            h, w = rgb.shape[:2]
            for q in quarters:
                if only is not None and (stem, q) not in only:
                    continue
                result = analyser.analyse(f"{stem}_turned{q}.png", turned_photo(rgb, q))
                doc = result.as_dict()
                v = verdict(result.known, result.horizon, truth, h, w, q)
                boundary = analyser.sky.boundary(result.rgb) if analyser.sky else None
                row = {"set": set_name, "photo": stem, "half": half, "quarters": q, **v,
                       "source": doc["horizon_source"], "doubt_deg": doc["horizon_orientation_doubt_deg"],
                       "turned_deg": doc["turned_deg"],
                       "std_px": doc["horizon_std_px"], "angle_std_deg": doc["horizon_angle_std_deg"],
                       "line": result.horizon.tolist(), "truth": turned_line(truth, h, w, q).tolist(),
                       "n_vertical": result.atlanta.n_vertical if result.atlanta is not None else None,
                       "boundary": None if boundary is None else {**boundary.as_dict(),
                                                                  "failed": boundary.failed_checks(analyser.sky.config)}}
                counts[(set_name, q, half, v["verdict"])] += 1
                if out:
                    out.write(json.dumps(row) + "\n")
                    out.flush()
                if v["verdict"] == "wrong":
                    print(f"WRONG {set_name} {stem} q={q} err={v['error']:.3f} roll={v['roll_deg']:.1f} "
                          f"sky_side={v['sky_side']} source={row['source']}", file=sys.stderr)
    for key in sorted({k[:3] for k in counts}):
        print(*key, {v: counts[(*key, v)] for v in ("right", "declined", "wrong")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
