"""Replay a published race file under the race's present sizing: is each budget's cell the same?

Every row keeps its published first-pass time (``ladder_seconds``, else ``seconds``); a ladder ends
where the present `--time-cap` / `--adaptive-cap` would have ended it; the present `race.finalists`
take their published re-timed medians, every other row its first-pass time; `race.race_table` then
gives each cell, printed beside the published one, with the quiet seconds the replayed run would
spend on ladders, compiles and the seven re-timing rounds (not the reference solves or imports).
A sizing of the race job is checked with it before a quiet rerun (issue 76):

    python benchmarks/race_replay.py docs/race_cpu/race_float64.json --time-cap 0.5 --adaptive-cap 4
"""

import argparse
import json
import sys

from race import BUDGETS, finalists, race_table


def replay(data, dtype, time_cap, adaptive_cap, rounds=7):
    """Print each scene's replayed cells against the published ones; return (seconds, cells changed)."""
    total, changed = 0.0, 0
    for scene, found in data["scenes"].items():
        kept, by_method, seconds = [], {}, 0.0
        for r in found["rows"]:
            by_method.setdefault(r["method"], []).append(r)
        for rows in by_method.values():
            seconds += rows[0]["compile_s"]
            for r in rows:
                first = r.get("ladder_seconds", r["seconds"])
                kept.append(dict(r, seconds=first, retimed=r["seconds"]))
                seconds += first
                if first > (time_cap if r["kind"] == "fixed" else adaptive_cap):
                    break
        final = finalists(kept, BUDGETS[dtype])
        for r in final:
            r["seconds"] = r["retimed"]
        seconds += rounds * sum(r["seconds"] for r in final)
        print(f"{scene}: {len(kept)} of {len(found['rows'])} rows, {len(final)} finalists, ~{seconds:.0f} s")
        cells = zip(race_table(kept, BUDGETS[dtype]), found["table"], strict=True)
        for (budget, ours, _, ratio), published in cells:
            same = (ratio is None) == (published["ratio"] is None) and (
                ratio is None or abs(ratio - published["ratio"]) <= 1e-9 * ratio
            )
            changed += not same
            mine = "—" if ratio is None else f"{ratio:.2f}"
            theirs = "—" if published["ratio"] is None else f"{published['ratio']:.2f}"
            method = ours and ours["method"]
            print(f"  {budget:.0e}: {method} {mine} (published {theirs}){'' if same else '  CHANGED'}")
        total += seconds
    return total, changed


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("path", help="a race results file (race_DTYPE.json)")
    parser.add_argument("--time-cap", type=float, required=True)
    parser.add_argument("--adaptive-cap", type=float, required=True)
    opts = parser.parse_args(argv)
    data = json.loads(open(opts.path).read())
    total, changed = replay(data, data["options"]["dtype"], opts.time_cap, opts.adaptive_cap)
    print(f"~{total / 60:.1f} quiet min of ladders, compiles and re-timing; {changed} cell(s) changed")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
