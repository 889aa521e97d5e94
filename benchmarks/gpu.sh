#!/usr/bin/env bash
# The GPU measurements of docs/performance.md ("On a GPU"), in one call of the lent machine.
#
#   OUT=/some/folder bash benchmarks/gpu.sh                      # every step: about 11 minutes
#   OUT=/some/folder STEPS=throughput,race_viscous bash benchmarks/gpu.sh   # under one call's 10
#
# Runs from the repository root with the machine's own python3 (jax with CUDA, diffrax,
# equinox, optax are in its image); jaxrot is imported from the checkout, and jax_md (not in the
# image) from ./.gpu_site when that folder holds it (copy jax_md, jraph, ml_collections,
# e3nn_jax and frozendict with their dist-info folders from a Python 3.12 site-packages).
# Each step has its own time limit and writes its own file under $OUT, most important first, so a
# call stopped early still returns what finished: throughput in float32 at 1e6 and 1e7 bodies
# without `stage` barriers (GPU default) against jax_md (`throughput`), the rotor's while loop
# with 1, 2, 4 and 8 DMV steps per iteration, and with XLA's command buffers as a per-program
# compiler option (`rotor_loop`) and as the process's flag (`command_buffers`), the race of the two
# scenes that miss 5x on the CPU (`race_viscous`, `race_dipole`; `race_dipole_cmdbuf` with the
# command-buffer flag for every program), the kernels of one step against a copy's and an exponential's
# (`passes`; `passes_pad` with vectors built by padded sums, an experiment not kept), then the same
# throughput with barriers (`barriers`); `throughput_defaults` is `throughput` without jaxrot's compiler
# options. Seen on an H100 (2026-11-26, 0ed6f8e): throughput 138 s, throughput_defaults 127 s, barriers
# 141 s, passes 31 s (47 s with the component-major programs, d0e1d6a+), passes_pad 33 s. Seen on an H200
# (2026-11-26): throughput 102 s, rotor_loop 77 s (before its command-buffer rows), command_buffers 42 s,
# a race about 200 s; on an H100 (2026-11-26): rotor_loop 135 s, command_buffers 45 s, race_dipole
# 219 s, race_dipole_cmdbuf 205 s (RACE_SCHEMES=splitting,rkmk_dopri8,rkmk_dopri8_cayley,srkn6b,srkn14a); a
# lent machine allows 10 minutes per call, so run the steps in two or three calls (STEPS names
# those of one call).
set -u
: "${OUT:?set OUT to the folder for the results}"
export PYTHONUNBUFFERED=1 PYTHONPATH="$PWD:$PWD/.gpu_site"
STEPS=",${STEPS:-throughput,throughput_defaults,rotor_loop,command_buffers,race_viscous,race_dipole,race_dipole_cmdbuf,passes,passes_pad,barriers},"
PY=${PYTHON:-python3}
# jaxrot reads its version from its installed metadata; the checkout is imported, not installed.
version=$($PY -c "import tomllib; print(tomllib.load(open('pyproject.toml', 'rb'))['project']['version'])")
mkdir -p ".gpu_site/jaxrot-$version.dist-info"
printf 'Metadata-Version: 2.1\nName: jaxrot\nVersion: %s\n' "$version" >".gpu_site/jaxrot-$version.dist-info/METADATA"
LOG="$OUT/gpu.log"
step() {  # step KEY SECONDS NAME COMMAND...: runs when STEPS names KEY
    local key=$1 limit=$2 name=$3
    shift 3
    [[ $STEPS == *",$key,"* ]] || return 0
    echo "== $name (limit ${limit}s) $(date -u +%T)" | tee -a "$LOG"
    local start=$SECONDS
    timeout "$limit" "$@" 2>&1 | grep -v -E "^\s*$|it/s\]$" | tee -a "$LOG"
    echo "== $name: exit ${PIPESTATUS[0]} after $((SECONDS - start)) s" | tee -a "$LOG"
}
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem,memory.used,memory.total --format=csv | tee -a "$LOG"
$PY -c "import jax, diffrax, jaxrot; print('jax', jax.__version__, jax.devices(), 'diffrax', diffrax.__version__)" 2>&1 | tee -a "$LOG"
$PY -c "import jax_md; print('jax_md ok')" 2>&1 | tail -1 | tee -a "$LOG"

# The second- and first-order schemes lose every race budget on the CPU by far; leaving them out
# keeps each race inside its limit.
RACE_SCHEMES=${RACE_SCHEMES:-splitting,rkmk4,rkmk_dopri5,rkmk_dopri8,rkmk_dopri8_cayley,srkn6b,srkn14a}
TP=(benchmarks/throughput.py --n "${TP_N:-1000000,10000000}" --dtype float32 --work "${TP_WORK:-3e8}" --repeats 5)
RACE=(benchmarks/race.py --dtype float64 --n "${RACE_N:-1000}" --time-cap 0.3 --repeats 2 --schemes "$RACE_SCHEMES")
step throughput 150 "throughput, no barriers, jax_md" $PY "${TP[@]}" --barriers off --json "$OUT/tp_f32_nobar.json"
# The same programs compiled with XLA's defaults instead of jaxrot.compiler_options() (on a GPU:
# command buffers holding while loops), to show what the option does to a rollout.
step throughput_defaults 150 "throughput, no barriers, XLA defaults" $PY "${TP[@]}" --barriers off --no-peer \
    --xla-defaults --json "$OUT/tp_f32_nobar_xla_defaults.json"
# Command buffers as the per-program option jaxrot.compiler_options() passes on a GPU.
step rotor_loop 240 "rotor loop batch, and command buffers as a compiler option" $PY benchmarks/rotor_loop.py \
    --fixed-substeps 2 --command-buffers --json "$OUT/rotor_loop.json"
# The same with XLA's CUDA-graph command buffers holding while loops and conditionals (a user's flag).
CB_FLAG=--xla_gpu_enable_command_buffer=+WHILE,+CONDITIONAL
step command_buffers 120 "rotor loop batch, command buffers" env XLA_FLAGS=$CB_FLAG \
    $PY benchmarks/rotor_loop.py --batches 1,4 --fixed-substeps 2 --json "$OUT/rotor_loop_cmdbuf.json"
step race_viscous 260 "race viscous_drag" $PY "${RACE[@]}" --scenes viscous_drag --out "$OUT/race_viscous_drag"
step race_dipole 260 "race dipole_rotating_field" $PY "${RACE[@]}" --scenes dipole_rotating_field --out "$OUT/race_dipole"
# Both sides of the race compiled with command buffers holding while loops (a user's flag, so every
# program gets it: diffrax's adaptive loops too).
step race_dipole_cmdbuf 260 "race dipole_rotating_field, command buffers" env XLA_FLAGS=$CB_FLAG \
    $PY "${RACE[@]}" --scenes dipole_rotating_field --out "$OUT/race_dipole_cmdbuf"
# Kernels per step and time per particle-step against three floors (a copy, one
# exponential with jaxrot's quaternion functions, the same on components).
step passes 150 "kernels per step" $PY benchmarks/gpu_passes.py --n 10000000 --out "$OUT/passes"
# The same with vectors assembled by sums of padded pieces instead of concatenations (experiment).
step passes_pad 150 "kernels per step, padded sums" $PY benchmarks/gpu_passes.py --n 10000000 --pad-concat \
    --out "$OUT/passes_pad"
step barriers 150 "throughput, barriers" $PY "${TP[@]}" --barriers on --no-peer --json "$OUT/tp_f32_bar.json"
ls -R "$OUT"
