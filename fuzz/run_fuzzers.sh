#!/usr/bin/env bash
# Runs every libFuzzer binary of a FACEDYN_FUZZ=ON build for a fixed time, one at a time (nice
# 10: the machine is shared), each from a scratch copy of its seed corpus and regressions (the
# tree's corpus is never grown by a run), and prints per target the executions and any crash
# file. Usage: fuzz/run_fuzzers.sh BUILD_DIR SECONDS [TARGET...]   (default: every target)
# Work files ($FUZZ_WORK, default BUILD_DIR/fuzz-work): BUILD_DIR/fuzz-work/<target>/{corpus,crash-*,log}; summary BUILD_DIR/fuzz-work/summary.tsv
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
build="$(cd "$1" && pwd)"
seconds="$2"
shift 2
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  # Every fuzz target the build has (fuzz/CMakeLists.txt), so a new one is never left out.
  for bin in "$build"/fuzz/fuzz_*; do
    [ -x "$bin" ] && [ -f "$bin" ] && targets+=("${bin##*/fuzz_}")
  done
  if [ ${#targets[@]} -eq 0 ]; then echo "fuzz: no fuzz_* binaries in $build/fuzz" >&2; exit 1; fi
fi
work="${FUZZ_WORK:-$build/fuzz-work}"  # FUZZ_WORK: run two lists side by side
mkdir -p "$work"
work="$(cd "$work" && pwd)"  # absolute: each fuzzer runs from inside its own work directory
summary="$work/summary.tsv"
printf 'target\tseconds\texecutions\tcrashes\n' > "$summary"
failed=0
for t in "${targets[@]}"; do
  bin="$build/fuzz/fuzz_$t"
  if [ ! -x "$bin" ]; then echo "fuzz: $bin is not built" >&2; failed=1; continue; fi
  dir="$work/$t"
  rm -rf "$dir/corpus"
  rm -f "$dir"/crash-* "$dir"/leak-* "$dir"/timeout-* "$dir"/oom-* "$dir"/slow-unit-*
  mkdir -p "$dir/corpus"
  for seeds in "$here/corpus/$t" "$here/regressions/$t"; do
    [ -d "$seeds" ] && cp -r "$seeds/." "$dir/corpus/"
  done
  # The shipped configuration files are seeds too for the config parsers.
  case "$t" in
    drive_profile) cp "$here"/../config/drives/*.yaml "$dir/corpus/" ;;
    rig_config) cp "$here"/../config/rigs/*.yaml "$dir/corpus/" ;;
    sweep_script) cp "$here"/../config/sweeps/*.yaml "$dir/corpus/" ;;
    capture_config) cp "$here"/../config/capture/*.yaml "$dir/corpus/" ;;
  esac
  case "$t" in
    modbus_reply|drive_request) max_len=512 ;;
    *) max_len=4096 ;;
  esac
  echo "fuzz: $t for ${seconds}s (max_len $max_len)"
  start=$(date +%s)
  (cd "$dir" && nice -n 10 "$bin" -max_total_time="$seconds" -max_len="$max_len" -timeout=10 \
     -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$dir/" corpus) > "$dir/log" 2>&1
  rc=$?
  elapsed=$(( $(date +%s) - start ))
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$dir/log" | grep -o '[0-9]*$' | tail -1)
  crashes=$(ls "$dir" | grep -E '^(crash|leak|timeout|oom|slow-unit)-' || true)
  printf '%s\t%s\t%s\t%s\n' "$t" "$elapsed" "${execs:-?}" "$(echo $crashes)" >> "$summary"
  echo "fuzz: $t: ${elapsed}s, ${execs:-?} executions, exit $rc"
  for c in $crashes; do echo "fuzz: $t: finding $dir/$c"; failed=1; done
  if [ $rc -ne 0 ] && [ -z "$crashes" ]; then failed=1; tail -20 "$dir/log"; fi
done
echo
column -t -s $'\t' "$summary"
exit $failed
