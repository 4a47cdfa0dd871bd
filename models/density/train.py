"""Train a density network on the synthetic dataset (PyTorch; the ``training`` extra).

Run (CPU or CUDA, whichever is there)::

    .venv/bin/python -m models.density.train --arch lite --data data/synth --out runs/train/lite --steps 4000

``--loss mse`` (the default) trains against Gaussian head maps; ``--loss bayesian`` is Ma et al.'s Bayesian Loss,
which collapsed to an empty map within a few hundred steps when training these small networks from scratch here
(models/density/MODEL_CARD.md).

Writes ``OUT/model.pt`` (weights, architecture, loss, the training log) and ``OUT/training.json`` (the log: loss
per step range, validation count MAE, wall time, device). The best checkpoint on the validation frames (the last
``--val-frames`` of the training split, never the held-out split) is kept.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import platform
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from torch.utils.data import DataLoader

from models.data.real_ground import TRAIN, RealGround, load_ground, split_validation
from models.density.architectures import Architecture, build, parameter_count
from models.density.calibration import fit_floor_and_scale
from models.density.dataset import WORKING_GSD_M_PER_PX, CrowdCrops, LabelledFrame, collate, load_frames
from models.density.losses import OCCUPANCY_THRESHOLD, LossKind, density_loss
from models.density.preprocess import OUTPUT_STRIDE, to_input
from models.density.pretrained import PretrainedStages

logger = logging.getLogger(__name__)


def validate(model: torch.nn.Module, frames: list[LabelledFrame], device: torch.device) -> dict[str, float]:
    """Count MAE, RMSE and bias on whole frames, raw and after the best floor and scale (as the export fits them).

    The calibrated MAE selects the checkpoint: the raw sum is dominated by the small floor on empty ground.
    """
    model.eval()
    maps = []
    with torch.no_grad():
        for frame in frames:
            x = torch.from_numpy(to_input(frame.image_bgr))[None].to(device)
            maps.append(model(x)[0, 0].cpu().numpy())
    model.train()
    counts = [len(f.heads_px) for f in frames]
    e = np.array([float(m.sum()) for m in maps]) - np.asarray(counts, np.float64)
    _, _, best = fit_floor_and_scale(maps, counts)
    recall, false_occupied = occupancy_scores(maps, [f.heads_px for f in frames], [f.person_mask for f in frames])
    return {
        "count_mae": float(np.abs(e).mean()),
        "count_rmse": float(np.sqrt((e**2).mean())),
        "bias": float(e.mean()),
        "count_mae_calibrated": best,
        "head_recall": recall,
        "false_occupied": false_occupied,
        "occupancy_score": false_occupied + 10.0 * max(0.0, 0.99 - recall),
    }


def real_ground_occupied(
    model: torch.nn.Module, ground: list[RealGround], device: torch.device, threshold: float = OCCUPANCY_THRESHOLD
) -> float:
    """Median occupied share of the cells of whole real frames with nobody in them, at their GSD and at twice it
    (the deployed threshold, no dilation)."""
    model.eval()
    shares = []
    with torch.no_grad():
        for frame in ground:
            for factor in (1.0, 0.5):
                image = frame.image_bgr
                if factor != 1.0:
                    image = np.asarray(cv2.resize(image, None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA))
                h, w = image.shape[:2]
                image = image[: h - h % OUTPUT_STRIDE, : w - w % OUTPUT_STRIDE]
                x = torch.from_numpy(to_input(np.ascontiguousarray(image)))[None].to(device)
                density = model(x)[0, 0].cpu().numpy()
                shares.append(float((density >= threshold).mean()))
    model.train()
    return float(np.median(shares)) if shares else math.nan


def occupancy_scores(
    maps: list[np.ndarray],
    heads_px: list[np.ndarray],
    person_masks: list[np.ndarray],
    threshold: float = OCCUPANCY_THRESHOLD,
) -> tuple[float, float]:
    """At the deployed threshold, without dilation: the share of heads with an occupied cell in their 3x3 cell
    neighbourhood, and the occupied share of the cells farther than 4 cells from every person pixel.

    ``maps`` (h, w) people per cell at stride 4; ``heads_px`` (K, 2) (u, v) frame pixels; masks (H, W) bool.
    """
    found = total = 0
    occupied_far = far_cells = 0
    for m, heads, mask in zip(maps, heads_px, person_masks, strict=True):
        occupied = m >= threshold
        h, w = occupied.shape
        for u, v in heads:
            r, c = int(v // OUTPUT_STRIDE), int(u // OUTPUT_STRIDE)
            found += bool(occupied[max(0, r - 1) : r + 2, max(0, c - 1) : c + 2].any())
            total += 1
        person_cells = cv2.resize(mask.astype(np.uint8), (w, h), interpolation=cv2.INTER_AREA) > 0
        near = cv2.dilate(person_cells.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
        occupied_far += int((occupied & ~near).sum())
        far_cells += int((~near).sum())
    return (found / total if total else 1.0), (occupied_far / far_cells if far_cells else 0.0)


def train(
    arch: Architecture,
    loss_kind: LossKind,
    data_dir: Path,
    out_dir: Path,
    steps: int,
    batch: int = 16,
    crop_px: int = 256,
    lr: float = 1e-3,
    seed: int = 0,
    workers: int = 2,
    val_frames: int = 40,
    limit_frames: int | None = None,
    sigma_px: float = 4.0,
    device_name: str | None = None,
    validate_every: int = 500,
    distractors: bool = True,
    scale_range: tuple[float, float] = (0.7, 1.4),
    real_ground_dirs: tuple[Path, ...] = (),
    real_negative_fraction: float = 0.0,
    composite_fraction: float = 0.0,
    real_gsd_m_per_px: tuple[float, float] = WORKING_GSD_M_PER_PX,
    real_detail_fraction: float = 0.0,
    backbone_lr_scale: float = 1.0,
    frozen_stages: int = 0,
) -> dict[str, Any]:
    """Train and save; returns the training log (also written to ``out_dir/training.json``).

    ``out_dir/model.pt`` is the checkpoint with the best validation score, ``out_dir/last.pt`` the last one.

    With ``real_ground_dirs`` (sites of ``sitl/world/ground``), their *training* frames give the real negatives and the
    composites' backgrounds; their held-out frames are never read here, and a site not named is never read at all
    (``models/eval/real.py`` scores a model on all frames of the sites it did not train on: the metadata names them).
    ``backbone_lr_scale``: the learning rate of a pretrained backbone (``yolox-lite``) relative to the rest; 0
    freezes it. ``frozen_stages``: its first stages (those that compute its first outputs: YOLOX-nano's stem and
    stride-4 stage for 1) frozen, the rest at ``backbone_lr_scale``.
    """
    start = time.monotonic()
    torch.manual_seed(seed)
    device = torch.device(device_name or ("cuda" if torch.cuda.is_available() else "cpu"))
    frames = load_frames(data_dir / "train", limit_frames)
    n_val = min(val_frames, max(1, len(frames) // 10))
    train_frames, val_set = frames[:-n_val], frames[-n_val:]
    ground: list[RealGround] = []
    real_val: list[RealGround] = []
    for site_dir in real_ground_dirs:
        # Every tenth real frame (number ending in 2) is validation: never trained on, watched during training.
        site_train, site_val = split_validation(load_ground(TRAIN, site_dir))
        ground += site_train
        real_val += site_val
    dataset = CrowdCrops(
        train_frames,
        crop_px,
        samples_per_epoch=batch * min(steps, 500),
        seed=seed,
        distractors=distractors,
        scale_range=scale_range,
        real_ground=ground,
        real_negative_fraction=real_negative_fraction,
        composite_fraction=composite_fraction,
        real_gsd_m_per_px=real_gsd_m_per_px,
        real_detail_fraction=real_detail_fraction,
    )
    loader = DataLoader(
        dataset,
        batch_size=batch,
        shuffle=False,
        num_workers=workers,
        collate_fn=collate,
        drop_last=True,
        persistent_workers=False,
    )
    model = build(arch).to(device)
    backbone = getattr(model, "backbone", None)
    pretrained = list(backbone.parameters()) if isinstance(backbone, torch.nn.Module) else []
    frozen = pretrained if backbone_lr_scale == 0.0 else []
    if frozen_stages and isinstance(backbone, PretrainedStages):
        frozen = frozen or backbone.stages.stage_parameters(frozen_stages)
    for parameter in frozen:
        parameter.requires_grad_(False)
    held = {id(p) for p in pretrained}
    pretrained = [p for p in pretrained if p.requires_grad]
    rates = [lr]
    groups = [{"params": [p for p in model.parameters() if id(p) not in held], "lr": lr}]
    if pretrained and backbone_lr_scale > 0.0:
        rates.append(lr * backbone_lr_scale)
        groups.append({"params": pretrained, "lr": rates[-1]})
    optimiser = torch.optim.AdamW(groups, lr=lr, weight_decay=1e-4)
    schedule = torch.optim.lr_scheduler.OneCycleLR(
        optimiser, max_lr=rates, total_steps=steps, pct_start=max(0.05, 3 / steps)
    )
    log: dict[str, Any] = {
        "architecture": arch.value,
        "loss": loss_kind.value,
        "parameters": parameter_count(model),
        "steps": steps,
        "batch": batch,
        "crop_px": crop_px,
        "lr": lr,
        "sigma_px": sigma_px,
        "distractors": distractors,
        "scale_range": list(scale_range),
        "real_ground": str(real_ground_dirs[0]) if len(real_ground_dirs) == 1 else None,
        "real_ground_sites": [d.name for d in real_ground_dirs],
        "backbone_lr_scale": backbone_lr_scale if held else None,
        "frozen_stages": frozen_stages if held else None,
        "real_ground_frames": [g.name for g in ground],
        "real_ground_validation_frames": [g.name for g in real_val],
        "real_negative_fraction": real_negative_fraction,
        "composite_fraction": composite_fraction,
        "real_gsd_m_per_px": list(real_gsd_m_per_px),
        "real_detail_fraction": real_detail_fraction,
        "seed": seed,
        "train_frames": len(train_frames),
        "val_frames": len(val_set),
        "device": torch.cuda.get_device_name(device) if device.type == "cuda" else platform.processor() or "cpu",
        "torch": str(torch.__version__),
        "history": [],
    }
    # The MSE models keep the checkpoint that counts best; the margin loss speaks occupancy, so its checkpoint is
    # the one with the least false-occupied ground at a head recall of 0.99 (each missed point of recall costs 10).
    select_by = "occupancy_score" if loss_kind is LossKind.MSE_MARGIN else "count_mae_calibrated"
    best: tuple[float, dict[str, torch.Tensor]] | None = None
    step, running, count = 0, 0.0, 0
    model.train()
    while step < steps:
        for images, points in loader:
            images = images.to(device, non_blocking=True)
            points = [p.to(device) for p in points]
            loss = density_loss(loss_kind, model(images), points, OUTPUT_STRIDE, sigma_px)
            optimiser.zero_grad(set_to_none=True)
            loss.backward()  # type: ignore[no-untyped-call]
            torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
            optimiser.step()
            schedule.step()
            loss_value = float(loss.detach())
            if not math.isfinite(loss_value):
                raise RuntimeError(f"training diverged at step {step}: loss {loss_value}")
            running, count, step = running + loss_value, count + 1, step + 1
            if step % validate_every == 0 or step == steps:
                metrics = validate(model, val_set, device)
                if real_val:
                    metrics["real_val_occupied"] = real_ground_occupied(model, real_val, device)
                entry = {"step": step, "loss": running / count, **metrics, "elapsed_s": time.monotonic() - start}
                log["history"].append(entry)
                logger.info(
                    "step %d loss %.3f val MAE %.2f bias %+.2f calibrated MAE %.2f head recall %.3f "
                    "false-occupied %.3f real ground occupied %.4f",
                    *(step, entry["loss"], metrics["count_mae"], metrics["bias"], metrics["count_mae_calibrated"]),
                    *(metrics["head_recall"], metrics["false_occupied"], metrics.get("real_val_occupied", math.nan)),
                )
                running, count = 0.0, 0
                if best is None or metrics[select_by] < best[0]:
                    state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
                    best = (metrics[select_by], state)
            if step >= steps:
                break
        dataset.epoch += 1
    assert best is not None
    log["selected_by"] = select_by
    log[f"best_val_{select_by}"] = best[0]
    log["wall_s"] = time.monotonic() - start
    out_dir.mkdir(parents=True, exist_ok=True)
    torch.save({"architecture": arch.value, "state_dict": best[1], "log": log}, out_dir / "model.pt")
    last = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}  # the end of the schedule, too
    torch.save(
        {"architecture": arch.value, "state_dict": last, "log": {**log, "selected_by": "last"}}, out_dir / "last.pt"
    )
    (out_dir / "training.json").write_text(json.dumps(log, indent=2) + "\n", encoding="utf-8")
    return log


def main() -> int:
    parser = argparse.ArgumentParser(description="Train an SLZ density network on the synthetic dataset.")
    parser.add_argument("--arch", choices=[a.value for a in Architecture], required=True)
    parser.add_argument("--loss", choices=[k.value for k in LossKind], default=LossKind.MSE.value)
    parser.add_argument("--data", type=Path, default=Path("data/synth"), help="folder with train/ inside")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--crop", type=int, default=256)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--limit-frames", type=int, default=None)
    parser.add_argument("--val-frames", type=int, default=40)
    parser.add_argument("--validate-every", type=int, default=500)
    parser.add_argument("--no-distractors", action="store_true", help="ablation: no procedural hard negatives")
    parser.add_argument(
        "--scale-range", type=float, nargs=2, default=(0.7, 1.4), metavar=("LOW", "HIGH"), help="crop rescale range"
    )
    parser.add_argument(
        "--real-ground", type=Path, action="append", default=[], help="a real site's folder (its training frames)"
    )
    parser.add_argument("--real-negatives", type=float, default=0.0, help="share of samples that are real ground")
    parser.add_argument("--composites", type=float, default=0.0, help="share of synthetic people on real ground")
    parser.add_argument(
        "--real-gsd",
        type=float,
        nargs=2,
        default=WORKING_GSD_M_PER_PX,
        metavar=("LOW", "HIGH"),
        help="GSD range (m/px) of the real negatives and composites (default: the companion's working range)",
    )
    parser.add_argument(
        "--real-detail",
        type=float,
        default=0.0,
        help="share of the composites whose people carry the real crop's fine texture",
    )
    parser.add_argument(
        "--backbone-lr-scale", type=float, default=1.0, help="pretrained layers' relative learning rate (0: frozen)"
    )
    parser.add_argument(
        "--frozen-stages", type=int, default=0, help="pretrained stages frozen from the input (1: stem and stride 4)"
    )
    parser.add_argument("--device", default=None, help="cpu or cuda (default: cuda when present)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    log = train(
        Architecture(args.arch),
        LossKind(args.loss),
        args.data,
        args.out,
        args.steps,
        batch=args.batch,
        crop_px=args.crop,
        lr=args.lr,
        seed=args.seed,
        workers=args.workers,
        val_frames=args.val_frames,
        limit_frames=args.limit_frames,
        device_name=args.device,
        validate_every=args.validate_every,
        distractors=not args.no_distractors,
        scale_range=tuple(args.scale_range),
        real_ground_dirs=tuple(args.real_ground),
        real_negative_fraction=args.real_negatives,
        composite_fraction=args.composites,
        real_gsd_m_per_px=tuple(args.real_gsd),
        real_detail_fraction=args.real_detail,
        backbone_lr_scale=args.backbone_lr_scale,
        frozen_stages=args.frozen_stages,
    )
    sys.stdout.write(
        f"{args.arch}: {log['parameters']} parameters, {args.steps} steps in {log['wall_s']:.0f} s on {log['device']}, "
        f"best validation {log['selected_by']} {log['best_val_' + log['selected_by']]:.3f}\n"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
