"""Re-fly the unsafe landings of the committed paper tables from their seeds with today's companion and perception.

Every SLZ mission of ``docs/results/paper_table1`` and ``docs/results/paper_table1_roi`` that touched down with a
person's body inside the footprint (landed, not a success) is flown again, in lockstep, by ``slz campaign replay``
from a copy of its campaign's spec and record. The table puts each mission's recorded outcome beside today's: a
mission is now **safe** when it lands clear of people or holds (no touchdown).

Run: ``.venv/bin/python -m bench.unsafe_replays [--out bench/results/unsafe_replays.json]`` (about a minute per
mission on two cores). Writes the replays under ``runs/unsafe_replays/`` and the table as JSON.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import yaml

from bench.machine import machine_context, save_report
from sitl.campaign.spec import load_campaign_spec

REPO_ROOT = Path(__file__).resolve().parent.parent


TABLES = {
    "paper_table1": ("docs/results/paper_table1", "mission_configs/campaigns/paper_table1.yaml"),
    "paper_table1_roi": ("docs/results/paper_table1_roi", "mission_configs/campaigns/paper_table1_roi.yaml"),
}
KEPT = (
    "landed",
    "success",
    "reason",
    "touchdown_nearest_m",
    "nearest_person_min_m",
    "aborts",
    "reselections",
    "touched_obstacle",
)


def unsafe_missions(results_path: Path) -> list[dict[str, Any]]:
    """Recorded SLZ missions (not the blind baseline) that landed with a body in the footprint."""
    rows: dict[str, dict[str, Any]] = {}
    for line in results_path.read_text(encoding="utf-8").splitlines():
        if line.strip():
            row = json.loads(line)
            rows[row["mission_id"]] = row  # a later line supersedes an earlier one
    return [r for r in rows.values() if r["strategy"] != "random" and r.get("landed") and not r.get("success")]


def replay(
    table: str, folder: Path, spec_path: Path, mission_id: str, work: Path, resume: bool = False
) -> dict[str, Any]:
    """One replay in ``work/<table>``; returns today's metrics (with ``resume``, those of an earlier replay there)."""
    campaign = work / table
    campaign.mkdir(parents=True, exist_ok=True)
    spec = load_campaign_spec(REPO_ROOT / spec_path)
    (campaign / "spec.yaml").write_text(yaml.safe_dump(spec.model_dump(mode="json"), sort_keys=False))
    shutil.copyfile(REPO_ROOT / folder / "results.jsonl", campaign / "results.jsonl")
    out = campaign / "replays" / mission_id
    saved = out / "today.json"
    if resume and saved.is_file():
        kept: dict[str, Any] = json.loads(saved.read_text(encoding="utf-8"))
        return kept
    shutil.rmtree(out, ignore_errors=True)
    slz = Path(sys.executable).with_name("slz")
    command = [str(slz), "campaign", "replay", str(campaign), mission_id, "--out", str(out)]
    run = subprocess.run(command, capture_output=True, text=True, timeout=900, check=False)
    text = run.stdout
    start = text.find("{")
    end = text.rfind("}")
    if start < 0 or end < start:
        raise RuntimeError(f"replay of {mission_id} printed no metrics (exit {run.returncode}): {run.stderr[-2000:]}")
    metrics: dict[str, Any] = json.loads(text[start : end + 1])
    saved.write_text(json.dumps(metrics, indent=1) + "\n", encoding="utf-8")
    return metrics


def main() -> int:
    parser = argparse.ArgumentParser(description="Re-fly the paper tables' unsafe landings from their seeds.")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "bench/results/unsafe_replays.json")
    parser.add_argument("--work", type=Path, default=REPO_ROOT / "runs/unsafe_replays")
    parser.add_argument("--resume", action="store_true", help="keep missions already replayed in --work")
    args = parser.parse_args()
    rows = []
    for table, (folder, spec_path) in TABLES.items():
        for recorded in unsafe_missions(REPO_ROOT / folder / "results.jsonl"):
            start = time.monotonic()
            today = replay(table, Path(folder), Path(spec_path), recorded["mission_id"], args.work, args.resume)
            safe = not today["landed"] or bool(today["success"])
            rows.append(
                {
                    "table": table,
                    "mission_id": recorded["mission_id"],
                    "recorded": {k: recorded.get(k) for k in KEPT},
                    "today": {k: today.get(k) for k in KEPT},
                    "safe": safe,
                    "wall_s": round(time.monotonic() - start, 1),
                }
            )
            t = today
            outcome = (
                f"landed {t['touchdown_nearest_m']:.2f} m from the nearest person"
                if t["landed"]
                else f"held ({t['reason']})"
            )
            sys.stdout.write(
                f"{table:17s} {recorded['mission_id']:24s} recorded: landed {recorded['touchdown_nearest_m']:.2f} m "
                f"from a person, a body in the footprint | today: {outcome}, {t['aborts']} aborts: "
                f"{'SAFE' if safe else 'UNSAFE'}\n"
            )
    safe_count = sum(r["safe"] for r in rows)
    sys.stdout.write(f"{safe_count} of {len(rows)} safe (landed clear of people or held)\n")
    save_report({"machine": machine_context(), "missions": rows, "safe": safe_count, "total": len(rows)}, args.out)
    return 0 if safe_count == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
