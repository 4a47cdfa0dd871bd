"""The regression gate: is a campaign significantly worse than a baseline on the same scenes?

A baseline (``slz campaign --write-baseline B.json``) keeps, per mission, the gated outcomes of one campaign: its
success and its warnings. A later campaign of the same spec flies the same scenes (the seeds depend only on the
master seed, the condition and the run), so each mission is a pair. For every strategy and gated outcome the gate
counts the pairs that got worse and those that got better and asks, with a one-sided exact binomial (McNemar) test,
whether "worse" is more frequent than chance would make it. The p-values of all the checks are adjusted together
(Holm), so the family of checks has the false-alarm rate ``alpha``. A fixed tolerance would be either blind on small
campaigns or noisy on large ones; this test is neither.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from companion.errors import SlzError
from sitl.campaign.record import CampaignResult, FlownMission, flown_missions
from sitl.campaign.spec import CampaignSpec
from sitl.campaign.stats import holm, mcnemar_exact

BASELINE_FORMAT = "slz-campaign-baseline/1"
GATED: dict[str, bool] = {"success": True, "warning_1m": False, "warning_1_5m": False}
"""The gated outcomes and whether True is the good value: rates of the report (their field metadata)."""


class GateError(SlzError):
    """A baseline that cannot be compared with this campaign (which file, what differs)."""


@dataclasses.dataclass(frozen=True)
class GateCheck:
    """One strategy's outcome against the baseline, over the paired missions."""

    strategy: str
    metric: str
    pairs: int
    baseline_rate: float
    candidate_rate: float
    worse: int
    """Pairs where this campaign's mission is worse than the baseline's."""
    better: int
    p_value: float
    """One-sided exact binomial test of ``worse`` against ``worse + better`` at 1/2."""
    p_adjusted: float
    """Holm-adjusted over all checks of the gate."""
    failed: bool


@dataclasses.dataclass(frozen=True)
class GateReport:
    """The gate's verdict, its checks and the missions whose gated outcomes changed."""

    alpha: float
    baseline: str
    checks: list[GateCheck]
    changes: list[str]
    unpaired: int
    """Missions of this campaign not compared: absent from the baseline, or not flown (infrastructure error)."""

    @property
    def failed(self) -> bool:
        """A check is significantly worse, or there was nothing to compare."""
        return not self.checks or any(c.failed for c in self.checks)

    def to_markdown(self) -> str:
        """A readable diff: the table of checks, then each changed mission."""
        verdict = "FAILED" if self.failed else "passed"
        lines = [
            f"# Regression gate: {verdict}",
            "",
            f"Against `{self.baseline}`. One-sided exact McNemar test per strategy and outcome, Holm-adjusted over "
            f"all {len(self.checks)} checks, family alpha {self.alpha:g}. Unpaired missions: {self.unpaired}.",
            "",
            "| strategy | outcome | pairs | baseline | this run | worse | better | p | p (Holm) | verdict |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for c in self.checks:
            lines.append(
                f"| {c.strategy} | {c.metric} | {c.pairs} | {100 * c.baseline_rate:.1f} % | "
                f"{100 * c.candidate_rate:.1f} % | {c.worse} | {c.better} | {c.p_value:.3g} | {c.p_adjusted:.3g} | "
                f"{'WORSE' if c.failed else 'ok'} |"
            )
        if not self.checks:
            lines.append("| - | - | 0 | - | - | - | - | - | - | nothing to compare |")
        lines += ["", f"Missions whose gated outcomes changed ({len(self.changes)}):", ""]
        lines += [f"- {change}" for change in self.changes] or ["- none"]
        return "\n".join(lines) + "\n"

    def to_json(self) -> dict[str, Any]:
        """JSON-able."""
        return {
            "failed": self.failed,
            "alpha": self.alpha,
            "baseline": self.baseline,
            "unpaired": self.unpaired,
            "checks": [dataclasses.asdict(c) for c in self.checks],
            "changes": self.changes,
        }


def make_baseline(spec: CampaignSpec, results: list[CampaignResult], commit: str | None = None) -> dict[str, Any]:
    """The baseline of a flown campaign: its spec's identity and each flown mission's gated outcomes."""
    missions = {
        r.mission_id: {"strategy": r.strategy, **{k: bool(getattr(r, k)) for k in GATED}}
        for r in flown_missions(results)
    }
    return {
        "format": BASELINE_FORMAT,
        "spec": spec.name,
        "master_seed": spec.master_seed,
        "commit": commit,
        "missions": dict(sorted(missions.items())),
    }


def read_baseline(path: Path) -> dict[str, Any]:
    """Load a baseline file (``GateError`` when it is not one)."""
    try:
        baseline: dict[str, Any] = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise GateError(f"cannot read baseline {path}: {exc}") from None
    if not isinstance(baseline, dict) or baseline.get("format") != BASELINE_FORMAT:
        raise GateError(f"{path} is not a campaign baseline (format {BASELINE_FORMAT!r})")
    return baseline


def check_against(
    spec: CampaignSpec, results: list[CampaignResult], baseline: dict[str, Any], alpha: float = 0.05, name: str = ""
) -> GateReport:
    """Compare a campaign's results with a baseline of the same spec, mission by mission.

    Raises
    ------
    GateError
        The baseline comes from another spec or master seed (its missions are other scenes), or ``alpha`` is not in
        (0, 1).
    """
    if not 0.0 < alpha < 1.0:
        raise GateError(f"alpha must be in (0, 1), got {alpha}")
    if baseline.get("spec") != spec.name or baseline.get("master_seed") != spec.master_seed:
        raise GateError(
            f"baseline {name or '?'} is of spec {baseline.get('spec')!r} with master seed "
            f"{baseline.get('master_seed')}; this campaign is {spec.name!r} with {spec.master_seed}: "
            "not the same scenes"
        )
    before: dict[str, dict[str, Any]] = baseline["missions"]
    paired: list[FlownMission] = [r for r in flown_missions(results) if r.mission_id in before]
    unpaired = len(results) - len(paired)
    changes: list[str] = []
    for r in sorted(paired, key=lambda r: r.mission_id):
        was = before[r.mission_id]
        moved = [f"{k} {was[k]} -> {bool(getattr(r, k))}" for k in GATED if bool(getattr(r, k)) != was[k]]
        if moved:
            changes.append(f"{r.mission_id}: " + ", ".join(moved))
    raw: list[tuple[str, str, int, float, float, int, int, float]] = []
    for strategy in sorted({r.strategy for r in paired}):
        rows = [r for r in paired if r.strategy == strategy]
        for metric, good in GATED.items():
            old = [before[r.mission_id][metric] for r in rows]
            new = [bool(getattr(r, metric)) for r in rows]
            # One-sided: pairs where only the baseline was good (worse now) outnumber those where only this run is.
            test = mcnemar_exact([o == good for o in old], [n == good for n in new], alternative="greater")
            raw.append(
                (strategy, metric, len(rows), sum(old) / len(rows), sum(new) / len(rows), test.only_a, test.only_b,
                 test.p_value)
            )  # fmt: skip
    adjusted = holm([item[-1] for item in raw])
    checks = [
        GateCheck(s, m, n, b, c, w, bt, p, pa, failed=pa < alpha)
        for (s, m, n, b, c, w, bt, p), pa in zip(raw, adjusted, strict=True)
    ]
    return GateReport(alpha, name, checks, changes, unpaired)
