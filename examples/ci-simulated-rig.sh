#!/usr/bin/env bash
# Hardware-free CI on the simulated rig: the job a studio runs on every change to its rig
# configs, sweep scripts or pipeline, with no drive, platform or camera attached. Each stage
# drives the same code paths as the real rig (a real Modbus TCP server in front of the simulated
# drive, the rig supervisor, the recorder, the dynamics tools) and the job fails on the first
# stage that does, naming it.
#
#   examples/ci-simulated-rig.sh [WORK_DIR]
#
# Environment: FACEDYN (the executable, default build/app/facedyn), FACEDYN_RIG_CONFIG (a Modbus
# TCP rig config, default config/rigs/sim-tcp.yaml), FACEDYN_SWEEP (the sweep script under test,
# default config/sweeps/demo.yaml), FACEDYN_SIM_PORT (the simulated drive's TCP port, default
# 15020: give parallel jobs different ports).
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
FACEDYN=${FACEDYN:-$ROOT/build/app/facedyn}
PORT=${FACEDYN_SIM_PORT:-15020}
RIG_CONFIG=${FACEDYN_RIG_CONFIG:-$ROOT/config/rigs/sim-tcp.yaml}
SWEEP=${FACEDYN_SWEEP:-$ROOT/config/sweeps/demo.yaml}
WORK=${1:-$(mktemp -d -t facedyn-ci.XXXXXX)}
mkdir -p "$WORK"
stage() { echo "== $*"; }
fail() { echo "ci-simulated-rig: FAILED: $*" >&2; exit 1; }

stage "rig config: $RIG_CONFIG on port $PORT"
[ -f "$RIG_CONFIG" ] || fail "no rig config $RIG_CONFIG"
[ -f "$SWEEP" ] || fail "no sweep script $SWEEP"
# The config under test with only its endpoint moved to this job's port (and a relative drive
# profile made absolute, since the copy lives elsewhere).
config_dir=$(cd "$(dirname "$RIG_CONFIG")" && pwd)
sed -E -e "s|^drive_profile: *([^/ ][^ ]*)|drive_profile: $config_dir/\1|" \
    -e "s|^  port: .*|  port: $PORT|" "$RIG_CONFIG" > "$WORK/rig.yaml"

stage "simulated drive and platform behind Modbus TCP"
"$FACEDYN" rig serve-sim --config "$WORK/rig.yaml" --seconds 600 > "$WORK/serve-sim.log" 2>&1 &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
for _ in $(seq 100); do
  "$FACEDYN" rig status --config "$WORK/rig.yaml" > /dev/null 2>&1 && break
  kill -0 $server 2>/dev/null || fail "serve-sim exited: $(tail -3 "$WORK/serve-sim.log")"
  sleep 0.1
done
"$FACEDYN" rig status --config "$WORK/rig.yaml" > /dev/null || fail "the simulated drive does not answer"

stage "sweep script: $SWEEP"
"$FACEDYN" sweep --config "$SWEEP" --rig "$WORK/rig.yaml" --check \
  || fail "the sweep script does not validate against the rig"
"$FACEDYN" sweep --config "$SWEEP" --rig "$WORK/rig.yaml" \
  --session "$WORK/sweep" --json > "$WORK/sweep.json" || fail "the sweep did not complete"
python3 - "$WORK/sweep.json" <<'PY' || fail "sweep gate"
import json, sys
result = json.load(open(sys.argv[1]))
if not result["steps"]:
    sys.exit("the sweep ran no step")
for step in result["steps"]:
    hold = step["hold"]
    print(f"  {step['target_hz']:6.2f} Hz  held {hold['seconds']:.1f} s at "
          f"{hold['mean_measured_hz']:.3f} Hz, max error {hold['max_abs_error_hz']:.3f} Hz")
    if not hold["max_abs_error_hz"] <= 0.05:
        sys.exit(f"step at {step['target_hz']} Hz held {hold['max_abs_error_hz']:.3f} Hz off")
PY

stage "capture session: config/capture/sim3.yaml (in-process simulated drive and cameras)"
"$FACEDYN" capture --config "$ROOT/config/capture/sim3.yaml" --session "$WORK/capture" \
  --take neutral_8hz || fail "capture"
"$FACEDYN" session check "$WORK/capture" || fail "the capture session is incomplete"

stage "dynamics removal on a simulated take, gated on its error against the exact truth"
"$FACEDYN" sim perform --expression neutral --motion platform --hz 11 --seconds 1.5 \
  --out "$WORK/takes/n11" > /dev/null || fail "sim perform"
"$FACEDYN" dynamics quasistatic --take "$WORK/takes/n11" --method platform-synchronous \
  --out "$WORK/takes/n11_q" || fail "dynamics quasistatic"
"$FACEDYN" dynamics eval --pred "$WORK/takes/n11_q" --truth "$WORK/takes/n11" \
  --input "$WORK/takes/n11" --json > "$WORK/eval.json" || fail "dynamics eval"
python3 - "$WORK/eval.json" <<'PY' || fail "removal gate"
import json, sys
reports = json.load(open(sys.argv[1]))["reports"]
removed, kept = reports["prediction"]["face"]["mean_mm"], reports["no_removal"]["face"]["mean_mm"]
print(f"  mean error {removed:.4f} mm (no removal {kept:.4f} mm)")
if not removed < 0.05 * kept:
    sys.exit(f"removal left {removed:.4f} mm of {kept:.4f} mm")
PY

echo "ci-simulated-rig: passed (outputs in $WORK)"
