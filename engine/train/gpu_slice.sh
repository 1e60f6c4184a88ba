#!/bin/bash
# One GPU slice of issue 22, as one command on the lent GPU machine (see README "Training", GPU slices).
#
# Prepare here once: ../shared/tools/gpu-machine-prep.sh (wheels in .whl/, GL loaders in .gl/); then call
# the device tool with carry [".whl", ".gl"] and the command `bash engine/train/gpu_slice.sh SECONDS`,
# where SECONDS is the wall time this script may use (it must end inside the call's limit: 575 in a 590 s
# call; a second call on the still-warm machine gets what is left, e.g. 240 in a 250 s call).
# It installs the project, checks EGL, with TIMINGS=1 times the update loop (paper at 512 and 256 px,
# small; bf16), with SYNTH_BENCH=1 measures the data generator, then trains `small` stage 1 until its deadline, resuming from
# resources/checkpoints/lirm-small-resume.safetensors when that exists. What comes back in $OUT:
# the float16 resume copy split in 15 MiB parts (slim.part*; `cat slim.part* > F` joins them), AdamW's
# second moments in 8 bits beside it (adamv.part*, joined into F's companion, the same name ending in
# .adam-v.safetensors: the next slice then needs no warm-up; second_moments.py) and logs.tar.gz
# (metrics.csv, eval.csv, run json, loss curves, timings, the log).
set -u
budget=${1:-540}
t0=$(date +%s)
left() { echo $((budget - ($(date +%s) - t0))); }
OUT=${OUT:-/tmp/out}
work=${SLICE_WORK:-/tmp/slice}  # the run, its logs and the slim copy before they are packed into $OUT
# Emptied first: a second call on a still-warm machine finds the first call's folder, and its run's metrics,
# log and bench would be packed again with its own (the fourth slice's were).
rm -rf "$work"
mkdir -p "$OUT" "$work"
log="$work/log.txt"
exec > >(tee -a "$log") 2>&1
export PYTHONUNBUFFERED=1

device=${DEVICE:-cuda}  # DEVICE=cpu: a dry run of the plumbing here (nothing installed, tiny budgets; tests/engine/train/test_gpu_slice.py)
if [ "$device" = cuda ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl &&
    python3 -m pip install -q --no-index --no-deps --no-build-isolation --target /tmp/site . || exit 1
  export PYTHONPATH=/tmp/site
  # A step without checkpointing peaks at 115 GiB of the H200's 139 with shapes that change from step to step
  # (the update sets' view counts): expandable segments spare the allocator freeing its cache and retrying
  # (the trainer logs the retries at the end; training steps took 2.1 s against the bench's 1.32).
  export PYTORCH_CUDA_ALLOC_CONF=${PYTORCH_CUDA_ALLOC_CONF:-expandable_segments:True}
  vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
  [ -f "$vendor" ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
  nvidia-smi --query-gpu=name,memory.total --format=csv
fi
lirm="python3 -m lirm.engine.cli"
# The paper's perceptual loss (LPIPS, VGG16) when its weights were carried in .lpips/ (the machine reaches no
# registry: `LIRM_LPIPS_DIR=.lpips lirm fetch lpips` here, then carry ".lpips" beside .whl and .gl); without
# them the trainer logs that LPIPS is skipped and uses the SSIM + gradient substitute, as the first six slices
# did.
# Always that folder, so that a dry run here does not take this machine's own cache and train another loss.
export LIRM_LPIPS_DIR=$PWD/.lpips
if [ -f .lpips/lpips-vgg.safetensors ]; then echo "perceptual loss: LPIPS (.lpips)"; else echo "perceptual loss: the SSIM + gradient substitute (no .lpips carried)"; fi
python3 -c "import moderngl; c = moderngl.create_standalone_context(backend='egl'); print('EGL:', c.info['GL_RENDERER'])" || exit 1
echo "[$(left) s left] installed"

# Update-loop timings (bf16 autocast on CUDA), each bounded so a hang cannot eat the slice; measured in
# the first slice (README, "The model"), so only with TIMINGS=1 (80 s of the slice).
if [ "${TIMINGS:-0}" = 1 ]; then
  timeout ${T_BENCH:-60} $lirm bench model --preset paper --device $device --updates 4 --no-baseline --json "$work/bench_paper512.json"
  timeout ${T_BENCH:-45} $lirm bench model --preset paper --device $device --updates 4 --no-baseline --image-size 256 --json "$work/bench_paper256.json"
  timeout ${T_BENCH:-45} $lirm bench model --preset small --device $device --updates 4 --no-baseline --json "$work/bench_small.json"
fi
# The training step itself (the slice's batch, both checkpointing settings, a profile): TRAIN_BENCH=1 (about 90 s).
if [ "${TRAIN_BENCH:-0}" = 1 ]; then
  timeout ${T_TRAIN_BENCH:-150} $lirm bench train --preset small --device $device --batch-scenes "${BATCH_SCENES:-16}" \
    --checkpointing both --steps 2 --profile --json "$work/bench_train.json" 2>&1 | grep -v USDT
fi
# One process's synthetic-scene rate on this machine's EGL (the training runs many such processes):
# only with SYNTH_BENCH=1 since the fifth slice (measured in four, 12.4-18.4 views per second; 18 s of
# training each time).
if [ "${SYNTH_BENCH:-0}" = 1 ]; then
  timeout ${T_BENCH:-45} $lirm bench synth --scenes "${SYNTH_SCENES:-6}" --views 8 --size 256
fi
echo "[$(left) s left] timings done"

# Checkpointing off where a step's 115 GiB fit (the H200: 1.32 s per step instead of 2.41 in the third
# slice's `lirm bench train`); on elsewhere (an 80 GB H100) and in the CPU dry run. CHECKPOINTING=on|off overrides.
checkpointing=${CHECKPOINTING:-auto}
if [ "$checkpointing" = auto ] && [ "$device" = cuda ]; then
  memory=$(nvidia-smi --query-gpu=memory.total --format=csv,noheader,nounits | head -1)
  [ "${memory:-0}" -ge 130000 ] && checkpointing=off
fi
# Loader processes: one makes 15.7-18.4 views of 256² a second on the H200's EGL (third slice), so a step's
# 16 scenes x 12 views take 8 processes about 1.5 s: enough for the 2.9 s step with checkpointing, not
# for the 1.3 s step without it, so 12 then (16 cores: the step's own process keeps one free).
if [ "$checkpointing" = off ]; then workers=${WORKERS:-12}; else workers=${WORKERS:-8}; fi
echo "gradient checkpointing: $checkpointing, $workers loader processes"
resume=()
# 12 views rendered per scene (stage 1's two update sets of up to 6; the trainer's default is 32) by
# one-thread loaders: the second slice's 14 processes rendering 32 views each with OpenCV's threads kept the
# 16 cores busy while the step's own process, which launches the GPU's kernels, needed one (3.37 s per step
# in training, 1.73 s in `lirm bench train` on the same GPU with the data made beforehand). SCENE_VIEWS=32
# gives the old data.
views=(--scene-views "${SCENE_VIEWS:-12}")
[ -f resources/checkpoints/lirm-small-resume.safetensors ] && resume=(--resume resources/checkpoints/lirm-small-resume.safetensors)
$lirm train --preset "${PRESET:-small}" --stage 1 --stage-steps "${STAGE_STEPS:-3000}" --batch-scenes "${BATCH_SCENES:-16}" \
  --workers "$workers" --device $device --out "$work/run" --checkpoint-every "${CHECKPOINT_EVERY:-100}" \
  --eval-every "${EVAL_EVERY:-100}" --eval-objects 2 --slim-copy "$work/slim.safetensors" --slim-only \
  --checkpointing "$checkpointing" "${resume[@]}" "${views[@]}" &
pid=$!
# The deadline is kept whatever the trainer is doing: a first SIGINT (to the trainer alone) stops at
# the end of its step with the slim copy; a second, STOP_GRACE s later, interrupts a step still waiting
# for its data (the slim copy of the last finished step is written on the way out); KILL_GRACE s after
# that it is killed and what exists is packed. A step takes about 2 s on the H200, so 12 and 10 s
# suffice there (the fifth slice's run ended 16 s after the first SIGINT, 10 of them a full checkpoint
# it no longer writes); the CPU dry run, whose steps are far slower, passes longer ones.
grace=${STOP_GRACE:-12}
kill_grace=${KILL_GRACE:-10}
stop_at=$(( $(left) - ${STOP_MARGIN:-35} ))
( sleep "$stop_at"; kill -INT $pid 2>/dev/null; sleep "$grace"; kill -INT $pid 2>/dev/null; sleep "$kill_grace"; kill -KILL $pid 2>/dev/null ) &
watchdog=$!
wait $pid
echo "[$(left) s left] training returned $?"
kill $watchdog 2>/dev/null

cp "$work/run"/metrics.csv "$work/run"/eval.csv "$work/run"/stage1_run.json "$work/run"/loss_curves.png "$work/" 2>/dev/null
[ -f "$work/slim.safetensors" ] && split -b 15M -d "$work/slim.safetensors" "$OUT/slim.part"
[ -f "$work/slim.adam-v.safetensors" ] && split -b 15M -d "$work/slim.adam-v.safetensors" "$OUT/adamv.part"
tar -C "$work" -czf "$OUT/logs.tar.gz" --exclude run --exclude slim.safetensors --exclude slim.adam-v.safetensors .
echo "[$(left) s left] packed: $(ls "$OUT")"
