#!/usr/bin/env bash
# Check our splat exports with real consumers (issue 6, "Exports"):
#   - the Khronos glTF validator (npm gltf-validator) on sample.glb;
#   - PlayCanvas splat-transform (npm @playcanvas/splat-transform) reads
#     sample.ply, sample.splat and sample.spz; what it decodes is compared
#     attribute by attribute with the exact parameters (quantisation bounds
#     per format, scripts/compare_exports.py).
# The samples (1000 random splats, SH degree 3) come from the splat crate's
# test `export::tests::write_samples_of_every_format_and_read_them_back`,
# which writes into $ROMOSPLAT_EXPORT_SAMPLES when set.
#
# Usage: scripts/check_exports.sh [OUT_DIR]     (default: a temp dir)
# Tools: used from PATH / `npm root -g` if present, else installed with
# `npm install -g` (set ROMOSPLAT_NPM_PREFIX to install under a prefix instead).
set -euo pipefail
cd "$(dirname "$0")/.."

out="${1:-$(mktemp -d -t romosplat-exports.XXXXXX)}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"

npm_install() {
  if [[ -n "${ROMOSPLAT_NPM_PREFIX:-}" ]]; then
    npm install --prefix "$ROMOSPLAT_NPM_PREFIX" --no-audit --no-fund "$@" >&2
  else
    npm install -g --no-audit --no-fund "$@" >&2
  fi
}
node_root() {
  if [[ -n "${ROMOSPLAT_NPM_PREFIX:-}" ]]; then echo "$ROMOSPLAT_NPM_PREFIX/node_modules"; else npm root -g; fi
}

command -v node >/dev/null || { echo "check_exports: node is not installed" >&2; exit 2; }
root="$(node_root)"
[[ -d "$root/gltf-validator" ]] || npm_install gltf-validator
[[ -d "$root/@playcanvas/splat-transform" ]] || npm_install @playcanvas/splat-transform
export NODE_PATH="$root"
st=(node "$root/@playcanvas/splat-transform/bin/cli.mjs")

echo "== writing samples into $out" >&2
ROMOSPLAT_EXPORT_SAMPLES="$out" cargo test --release -q -p splat --lib \
  export::tests::write_samples_of_every_format_and_read_them_back -- --exact >&2
ls -l "$out"/sample.* >&2

status=0
echo "== gltf-validator on sample.glb" >&2
node scripts/validate_glb.mjs "$out/sample.glb" || status=1

echo "== splat-transform reads sample.ply / sample.splat / sample.spz" >&2
want=$(( $(wc -l < "$out/sample_truth.csv") - 1 ))
args=()
for fmt in ply splat spz; do
  log="$out/$fmt.log"
  if ! "${st[@]}" -w "$out/sample.$fmt" "$out/decoded_$fmt.csv" >"$log" 2>&1; then
    echo "{\"tool\":\"splat-transform\",\"format\":\"$fmt\",\"ok\":false,\"log\":\"$log\"}"
    status=1
    continue
  fi
  got=$(( $(wc -l < "$out/decoded_$fmt.csv") - 1 ))
  echo "{\"tool\":\"splat-transform\",\"format\":\"$fmt\",\"ok\":$([[ $got == "$want" ]] && echo true || echo false),\"rows\":$got,\"expected\":$want}"
  [[ $got == "$want" ]] || status=1
  args+=("$fmt=$out/decoded_$fmt.csv")
done
if (( ${#args[@]} )); then
  python3 scripts/compare_exports.py "$out/sample_truth.csv" "${args[@]}" || status=1
fi
echo "== check_exports: $([[ $status == 0 ]] && echo OK || echo FAILED) ($out)" >&2
exit $status
