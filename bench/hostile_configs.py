"""How fast and how clearly ``slz fly --dry-run`` refuses each hostile config file (sitl/testing/hostile_configs.py).

Run: ``.venv/bin/python -m bench.hostile_configs``. Each file runs in its own ``slz fly --dry-run`` process (the
refusal must come before anything is started), timed from process start to exit; the load alone is also timed in
this process. Asserted: exit 2, no traceback, the field (or the document) named with one of the project's own
reasons, a message under 2,000 characters, every file refused within 1 s of loading. Prints and saves
``bench/results/hostile_configs.json`` with the machine's context.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.machine import machine_context, save_report
from companion.app.mission import load_mission_config
from companion.config import ConfigError
from sitl.testing.hostile_configs import fly_dry_run, hostile_configs

REPO_ROOT = Path(__file__).resolve().parent.parent


MAX_LOAD_S = 1.0


def main() -> int:
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for hostile in hostile_configs():
            path = Path(tmp) / f"{hostile.name}.yaml"
            path.write_bytes(hostile.content)
            t0 = time.perf_counter()
            try:
                load_mission_config(path)
                message = "ACCEPTED"
            except ConfigError as exc:
                message = str(exc)
            load_s = time.perf_counter() - t0
            t1 = time.perf_counter()
            run = fly_dry_run(path)
            process_s = time.perf_counter() - t1
            row = {
                "file": hostile.name,
                "bytes": len(hostile.content),
                "load_ms": round(1000 * load_s, 2),
                "process_s": round(process_s, 3),
                "exit": run.returncode,
                "traceback": "Traceback" in run.stderr,
                "named": hostile.refusal_problem(run.stderr) is None and hostile.refusal_problem(message) is None,
                "message_chars": len(run.stderr),
                "message": run.stderr.strip().splitlines()[-1][:160] if run.stderr.strip() else "",
            }
            rows.append(row)
            print(
                f"{row['file']:24s} {row['load_ms']:8.2f} ms load {row['process_s']:6.3f} s process  {row['message']}"
            )
    failures = [
        r
        for r in rows
        if r["exit"] != 2
        or r["traceback"]
        or not r["named"]
        or r["message_chars"] >= 2000
        or r["load_ms"] > 1000 * MAX_LOAD_S
    ]
    report = {
        "machine": machine_context(),
        "files": len(rows),
        "refused": sum(r["exit"] == 2 for r in rows),
        "max_load_ms": max(r["load_ms"] for r in rows),
        "max_process_s": max(r["process_s"] for r in rows),
        "median_process_s": sorted(r["process_s"] for r in rows)[len(rows) // 2],
        "failures": [r["file"] for r in failures],
        "rows": rows,
    }
    out = REPO_ROOT / "bench" / "results" / "hostile_configs.json"
    save_report(report, out)
    print(
        f"{report['refused']}/{report['files']} refused; slowest load {report['max_load_ms']} ms, slowest process "
        f"{report['max_process_s']} s; failures: {report['failures'] or 'none'}; saved {out}"
    )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
