# Sourced by the scripts: where builds go and where the shared inputs are.
# The target dir lives outside the clone so reruns on one machine reuse it.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/relevo/target}"
export CARGO_TERM_COLOR="${CARGO_TERM_COLOR:-never}"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export RELEVO_SHARED_DATA="${RELEVO_SHARED_DATA:-$REPO/../shared/data}"
