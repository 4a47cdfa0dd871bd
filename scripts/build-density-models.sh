#!/usr/bin/env bash
# Build the shipped density models from nothing: render the synthetic data, train both networks, export to ONNX
# with a parity check, quantize to INT8, evaluate on the held-out split and on the real reference frames, and
# time them. These are the commands behind models/density/MODEL_CARD.md (about two hours on 2 CPU cores).
# Needs the training extra: `make training`.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
DATA=${DATA:-data/synth}
RUNS=${RUNS:-runs/train}
OUT=models/density

# 1. Data, in two parallel chunks each: 1600 training frames at 8-40 m (the shipped models), 400 held-out frames
#    (style split) at 2-40 m (the evaluation's bands reach the final descent), and for the ablations below the same
#    1600 training scenes at 2-40 m.
render() {  # render SPLIT FRAMES OUT LOW_M HIGH_M
    local half=$(($2 / 2))
    "$PY" -m models.data.generate --split "$1" --frames "$half" --first 0 --out "$3" --altitude-m "$4" "$5" &
    "$PY" -m models.data.generate --split "$1" --frames "$half" --first "$half" --out "$3" --altitude-m "$4" "$5" &
    wait
}
LOW=${LOW:-data/synth_low}
render train 1600 "$DATA" 8 40
render heldout 400 "$DATA" 2 40
render train 1600 "$LOW" 2 40

# 2. Training (MSE against Gaussian head maps: the Bayesian Loss collapsed to empty maps from scratch here, see
#    the model card), best checkpoint on the last 40 training frames. The shipped lite model is the one trained
#    without the procedural hard negatives: it was the better of the two on the held-out split.
"$PY" -m models.density.train --arch lite --loss mse --no-distractors --data "$DATA" --out "$RUNS/lite" --steps 4000 \
    --batch 8 --crop 192 --workers 1 --validate-every 500
"$PY" -m models.density.train --arch ccnn --loss mse --data "$DATA" --out "$RUNS/ccnn" --steps 2000 --batch 8 --crop 128 \
    --workers 1 --validate-every 500
# The same lite network with the hard negatives (models/data/distractors.py), for the model card (not shipped).
"$PY" -m models.density.train --arch lite --loss mse --data "$DATA" --out "$RUNS/lite_distractors" --steps 4000 \
    --batch 8 --crop 192 --workers 1 --validate-every 500
"$PY" -m models.density.export --checkpoint "$RUNS/lite_distractors/model.pt" --out "$RUNS/lite_distractors.onnx" \
    --name slz-lite-distractors --version 0 --check-frames "$DATA/train"
# Ablations for real frames and low altitude (model card, "Low altitude and real frames"; none shipped): 2-40 m
# data; the same with the occupancy-margin loss, wider rescaling and the hard negatives; the same data with the
# hard negatives, foliage and CC0 photo textures included, and plain MSE.
"$PY" -m models.density.train --arch lite --loss mse --no-distractors --data "$LOW" --out "$RUNS/lite_low_mse" \
    --steps 4000 --batch 8 --crop 192 --workers 1 --validate-every 500
"$PY" -m models.density.train --arch lite --loss mse-margin --data "$LOW" --out "$RUNS/lite_low_margin" \
    --steps 4000 --batch 8 --crop 192 --workers 1 --validate-every 500 --scale-range 0.5 2.0
"$PY" -m models.density.train --arch lite --loss mse --data "$LOW" --out "$RUNS/lite_low_mse_foliage" \
    --steps 4000 --batch 8 --crop 192 --workers 1 --validate-every 500
for run in lite_low_mse lite_low_margin lite_low_mse_foliage; do
    "$PY" -m models.density.export --checkpoint "$RUNS/$run/model.pt" --out "$RUNS/$run.onnx" --name "$run" \
        --version 0 --check-frames "$LOW/train"
done

# 3. Export with parity against PyTorch (1e-4), and INT8 static quantization calibrated on training frames.
"$PY" -m models.density.export --checkpoint "$RUNS/lite/model.pt" --out "$OUT/slz_lite.onnx" --name slz-lite \
    --version 1 --check-frames "$DATA/train"
"$PY" -m models.density.export --checkpoint "$RUNS/ccnn/model.pt" --out "$OUT/slz_ccnn.onnx" --name slz-ccnn \
    --version 1 --check-frames "$DATA/train"
"$PY" -m models.density.quantize --model "$OUT/slz_lite.onnx" --out "$OUT/slz_lite_int8.onnx" \
    --calibration "$DATA/train" --frames 64

# 4. Evaluation: held-out split per altitude band as the companion runs the models (frames below about 16 m shrunk,
#    perception.model.min_gsd_m_per_px) and unshrunk; real frames (every set under ../shared/datasets, if any);
#    latency.
MODELS=(--model slz-lite="$OUT/slz_lite.onnx" --model slz-lite-int8="$OUT/slz_lite_int8.onnx"
    --model slz-ccnn="$OUT/slz_ccnn.onnx" --model blob-placeholder=models/blob_detector/blob_detector.onnx
    --model lite-2-40m="$RUNS/lite_low_mse.onnx" --model lite-2-40m-margin="$RUNS/lite_low_margin.onnx"
    --model lite-2-40m-foliage="$RUNS/lite_low_mse_foliage.onnx")
"$PY" -m models.eval.evaluate --data "$DATA/heldout" --out models/eval/results/heldout "${MODELS[@]}"
"$PY" -m models.eval.evaluate --data "$DATA/heldout" --out models/eval/results/heldout_unshrunk --min-gsd 0 \
    "${MODELS[@]}"
if [ -d ../shared/datasets ]; then
    "$PY" -m models.eval.real --out models/eval/results/real "${MODELS[@]}"
fi
"$PY" bench/density.py
