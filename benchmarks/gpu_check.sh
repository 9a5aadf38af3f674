#!/usr/bin/env bash
# The GPU run, prepared: everything a CUDA machine should be asked, in one go (under 8 minutes on one
# H100-class GPU), printed as one summary table followed by each part's own table.
#
#   bash benchmarks/gpu_check.sh              # on a CUDA machine, from the repository root's venv
#   bash benchmarks/gpu_check.sh --dry-run    # on the CPU at toy sizes: every part still runs (the tests do this)
#
# Parts: the tests marked cuda; one DDP step on all GPUs; a bf16 and an fp16 training step; the paper
# setting's training loop (640×192, batch 12, ResNet-18 from scratch) for the baseline and all three
# constraints in fp32 and bf16, with the loader's own samples/s beside them; the depth network's own
# images/s; and `predict` on a 1242×375 sequence, whose frames/s is set against the network's.
# Logs and data go to $OUT (default gpu_check/). Record the table with the machine it came from.
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python}
POSECONS=("$PY" -m posecons.cli)
OUT=${OUT:-gpu_check}
DRY=0
[[ "${1:-}" == "--dry-run" ]] && DRY=1
mkdir -p "$OUT"

if ((DRY)); then
  DEV=cpu GPUS=2 FRAMES=12
  SYNTH=(--drives 2 --frames "$FRAMES" --width 384 --height 128)
  SMALL=(--set model.height=64 --set model.width=128 --set model.num_layers=10 --set train.batch_size=2)
  LOOP=(--preset synth/demo --steps 1 --warmup 0 --set train.batch_size=2)
  NET=(--layers 10 --height 64 --width 128 --batches 2 --warmup 0 --repeats 1 --no-onnx)
else
  DEV=cuda GPUS=$($PY -c 'import torch; print(torch.cuda.device_count())') FRAMES=60
  SYNTH=(--drives 4 --frames "$FRAMES")  # KITTI's 1242×375
  SMALL=()
  LOOP=(--preset kitti/baseline --set model.pretrained=false --set data.num_workers=8 --steps 10 --warmup 3)
  NET=(--batches 1 16 --no-onnx)
fi
DATA=$OUT/data
DRIVE=$DATA/2020_01_01/2020_01_01_drive_0000_sync/image_02/data  # posecons synth's first drive
TRAIN=(--config synth/demo --data-path "$DATA" --set data.img_ext=.jpg --set train.val_every=off
  --set train.max_steps=2 --set train.image_every=0 --quiet --accelerator "$DEV" "${SMALL[@]}")

ROWS=()
LAST=0  # seconds the last part took
part() {  # part NAME COMMAND...: run it, log it, note its status and seconds
  local name=$1 start status=ok
  shift
  echo "[gpu_check] $name" >&2
  start=$(date +%s.%N)
  "$@" >"$OUT/$name.log" 2>&1 || status="FAILED (exit $?, $OUT/$name.log)"
  LAST=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  ROWS+=("| $name | $status | $LAST |")
}

[[ -d $DATA ]] || part data "${POSECONS[@]}" synth --out "$DATA" --ext jpg --neighbours 3 "${SYNTH[@]}"
part cuda-tests "$PY" -m pytest -q -m cuda tests
rm -rf "$OUT/ddp" "$OUT/bf16" "$OUT/fp16" "$OUT/predict"
part ddp-step "${POSECONS[@]}" train "${TRAIN[@]}" --out "$OUT/ddp" --devices "$GPUS"
part bf16-step "${POSECONS[@]}" train "${TRAIN[@]}" --out "$OUT/bf16" --set train.precision=bf16
if ((DRY)); then
  ROWS+=("| fp16-step | not on a CPU | 0 |")
else
  part fp16-step "${POSECONS[@]}" train "${TRAIN[@]}" --out "$OUT/fp16" --set train.precision=16
fi
part train-loop-fp32 "$PY" benchmarks/train_loop.py --data "$DATA" --device "$DEV" --variants baseline all "${LOOP[@]}"
part train-loop-bf16 "$PY" benchmarks/train_loop.py --data "$DATA" --device "$DEV" --variants baseline all \
  --no-loader-only --set train.precision=bf16 "${LOOP[@]}"
if ((DRY)); then  # compiling takes a minute on a CPU; tests/test_model.py covers the compiled losses
  ROWS+=("| train-loop-bf16-compiled | not in a dry run | 0 |")
else
  part train-loop-bf16-compiled "$PY" benchmarks/train_loop.py --data "$DATA" --device "$DEV" --variants baseline \
    --no-loader-only --set train.precision=bf16 --set train.compile_losses=true "${LOOP[@]}"
fi
part depth-net "$PY" benchmarks/inference.py --device "$DEV" "${NET[@]}"
part predict "${POSECONS[@]}" predict --checkpoint "$OUT/bf16/checkpoints/last.pt" --input "$DRIVE" --out "$OUT/predict" \
  --device "$DEV" --quiet
ROWS+=("| predict: $FRAMES frames (decode, network, writing; start-up included) | $(awk -v n="$FRAMES" -v t="$LAST" 'BEGIN { printf "%.2f frames/s", n / t }') | $LAST |")

echo
echo "gpu_check $( ((DRY)) && echo '--dry-run ')on $(hostname): $($PY -c 'import torch, platform
print(platform.processor() or platform.machine(), "·", torch.cuda.get_device_name() if torch.cuda.is_available() else "no GPU", "·", torch.cuda.device_count(), "GPU(s) · torch", torch.__version__)')"
echo
echo "| part | status | seconds |"
echo "|---|---|---|"
printf '%s\n' "${ROWS[@]}"
for log in train-loop-fp32 train-loop-bf16 train-loop-bf16-compiled depth-net; do
  [[ -f $OUT/$log.log ]] || continue
  echo
  echo "$log:"
  grep -E '^\||threads|GiB' "$OUT/$log.log"
done
! printf '%s\n' "${ROWS[@]}" | grep -q FAILED
