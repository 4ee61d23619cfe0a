#!/usr/bin/env bash
# The frozen frames' GPU checks, prepared for a session lent a GPU, in two parts that each end
# inside one device command's 10 minutes (every step under its own time limit, so that a slow
# one costs only itself):
#
#   bash bench/gpu_session.sh OUT 1    # about 6 minutes: correctness and a frame's split
#   bash bench/gpu_session.sh OUT 2    # about 6 minutes: frames/h and the GPU's busy share
#
# The runtime must be importable already (an offline machine: ../shared/tools/offline-gpu-bundle.sh
# unpacked on PYTHONPATH; PYTHON names the interpreter, python3 by default). Writes into OUT:
#   gpu.txt                 the GPU (nvidia-smi -L)
#   part 1:
#   frozen_frames.md        frozen against traced on cuda_ad_rgb, bytes and recordings (bench_frozen_frames)
#   render_2k_frozen.txt    a 2K frame's split at 4 spp, frozen (bench_render), and
#   render_2k_traced.txt    the same traced
#   part 2:
#   fph_frozen.md           the default build's frames/h, --workers auto (bench_fph), and
#   dmon_frozen.txt         the GPU's busy share (SM %) over it, once a second (nvidia-smi dmon)
#   fph_traced.md, dmon_traced.txt   the same with render.frozen off
set -u
out=${1:?usage: bash bench/gpu_session.sh OUT 1|2}
part=${2:?usage: bash bench/gpu_session.sh OUT 1|2}
py=${PYTHON:-python3}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
nvidia-smi -L > "$out/gpu.txt" 2>&1
if [ "$part" = 1 ]; then
    timeout 200 "$py" bench/bench_frozen_frames.py --variant cuda_ad_rgb --scenes wingcam55 dashcam75 \
        --frames 0 1 5 13 29 > "$out/frozen_frames.md" 2>&1
    for mode in frozen traced; do
        flag=$([ "$mode" = traced ] && echo --traced || true)
        timeout 90 "$py" bench/bench_render.py --variant cuda_ad_rgb --spp 4 --frames 6 $flag \
            > "$out/render_2k_$mode.txt" 2>&1
    done
else
    for mode in frozen traced; do
        flag=$([ "$mode" = traced ] && echo --traced || true)
        nvidia-smi dmon -s u -d 1 > "$out/dmon_$mode.txt" 2>&1 &
        dmon=$!
        timeout 170 "$py" bench/bench_fph.py --scenes wingcam55 --frames 320 --workers auto $flag \
            > "$out/fph_$mode.md" 2>&1
        kill "$dmon" 2>/dev/null
    done
fi
ls -l "$out"
