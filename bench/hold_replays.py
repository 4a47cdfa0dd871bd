"""Re-fly every SLZ hold of a campaign from its seed and say why it held, from the flight log and the ground truth.

Issue 33 asks that a hold be a decision the flight log explains, never a timeout from dithering. A campaign keeps
each mission's result, not its flight log; this flies each SLZ mission of a campaign folder that did not land again,
in lockstep, with ``slz campaign replay`` (which checks that the replay gives the campaign's result: the same seed
decides the same), and reads its flight log and truth with :mod:`sitl.campaign.hold_explain`: every landing point the
companion gave up and why, for the ones it gave up for a person how far the nearest body really was, and whether a
disc as large as the footprint was truly free in the landing area (what a perfect map would have landed on).

Run: ``.venv/bin/python -m bench.hold_replays runs/campaigns/paper_table1_roi [--jobs 2] [--resume]`` (a replay
takes one to five minutes of one core; ``--jobs`` flies that many at once, each SITL on its own ports). Writes the
replays under ``runs/hold_replays/<campaign>/`` and the table as JSON (``--out``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from bench.machine import machine_context, save_report
from sitl.campaign.hold_explain import explain_run
from sitl.campaign.runner import read_results

REPO_ROOT = Path(__file__).resolve().parent.parent


KEPT = ("reason", "hold_cause", "zones_chosen", "aborts", "reselections")


def holds(campaign: Path) -> list[dict[str, Any]]:
    """The campaign's SLZ missions (not the blind random baseline) without a touchdown, last result per mission."""
    rows = {r["mission_id"]: r for r in read_results(campaign / "results.jsonl") if "error" not in r}
    return [r for r in rows.values() if r["strategy"] != "random" and not r.get("landed")]


def replay(campaign: Path, mission_id: str, work: Path, resume: bool) -> dict[str, Any]:
    """Fly one mission again into ``work/<mission_id>``: its metrics and whether they equal the campaign's."""
    out = work / mission_id
    saved = out / "replay.json"
    if resume and saved.is_file():
        kept: dict[str, Any] = json.loads(saved.read_text(encoding="utf-8"))
        return kept
    slz = Path(sys.executable).with_name("slz")
    command = [str(slz), "campaign", "replay", str(campaign), mission_id, "--out", str(out)]
    start = time.monotonic()
    run = subprocess.run(command, capture_output=True, text=True, timeout=1800, check=False)
    text = run.stdout
    first, last = text.find("{"), text.rfind("}")
    if first < 0 or last < first:
        raise RuntimeError(f"replay of {mission_id} printed no metrics (exit {run.returncode}): {run.stderr[-2000:]}")
    result = {
        "metrics": json.loads(text[first : last + 1]),
        "same_as_campaign": "metrics identical to the campaign's result" in text,
        "wall_s": round(time.monotonic() - start, 1),
    }
    saved.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    return result


def repo_relative(path: Path) -> str:
    """``path`` relative to the repository (as the record is read on other machines), else as it is."""
    try:
        return str(path.relative_to(REPO_ROOT))
    except ValueError:
        return str(path)


def main() -> int:
    parser = argparse.ArgumentParser(description="Re-fly a campaign's SLZ holds and explain each from its flight log.")
    parser.add_argument("campaign", type=Path, nargs="?", default=REPO_ROOT / "runs/campaigns/paper_table1_roi")
    parser.add_argument("--work", type=Path, help="replays go here (default runs/hold_replays/<campaign name>)")
    parser.add_argument("--out", type=Path, help="JSON table (default bench/results/hold_replays_<campaign>.json)")
    parser.add_argument("--jobs", type=int, default=1, help="replays flown at once")
    parser.add_argument("--resume", action="store_true", help="keep missions already replayed in --work")
    parser.add_argument("--missions", nargs="*", help="only these mission ids")
    args = parser.parse_args()
    campaign = args.campaign.resolve()
    work = args.work or REPO_ROOT / "runs/hold_replays" / campaign.name
    out = args.out or REPO_ROOT / f"bench/results/hold_replays_{campaign.name}.json"
    recorded = [r for r in holds(campaign) if not args.missions or r["mission_id"] in args.missions]
    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        replays = list(pool.map(lambda r: replay(campaign, r["mission_id"], work, args.resume), recorded))
    rows = []
    for row, again in zip(recorded, replays, strict=True):
        explanation = explain_run(work / row["mission_id"])
        rows.append(
            {
                "mission_id": row["mission_id"],
                "recorded": {k: row.get(k) for k in KEPT},
                "same_as_campaign": again["same_as_campaign"],
                "wall_s": again["wall_s"],
                "explanation": explanation.to_json(),
            }
        )
        sys.stdout.write(
            f"{row['mission_id']:24s} {row.get('hold_cause')} | replay "
            f"{'identical' if again['same_as_campaign'] else 'DIFFERENT'} | {explanation.summary()}\n"
        )
    causes = Counter(str(r["recorded"]["hold_cause"]) for r in rows)
    verdicts = Counter(r["explanation"]["verdict"] for r in rows)
    same = sum(r["same_as_campaign"] for r in rows)
    free = sum((r["explanation"]["free_share"] or 0.0) >= 0.5 for r in rows)
    sys.stdout.write(
        f"{len(rows)} holds: by cause {dict(causes)}; by what the truth says {dict(verdicts)}; {free} with a truly "
        f"free disc of the footprint's size in the landing area for most of the flight; "
        f"{same} of {len(rows)} replays gave the campaign's result\n"
    )
    save_report(
        {
            "machine": machine_context(),
            "campaign": repo_relative(campaign),
            "holds": rows,
            "by_cause": dict(causes),
            "by_verdict": dict(verdicts),
            "truly_free_most_of_the_flight": free,
        },
        out,
    )
    return 0 if same == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
