#!/usr/bin/env bash
# Create .venv, make sure the system libraries the wheels link against exist, install graphloc.
# Called by `make demo` / `make test`; safe to run again (it only does what is missing).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}

# System libraries that binary wheels link but do not ship:
#   libusb-1.0 (Open3D), libgomp (Open3D, KISS-ICP), libGL/libX11 bits are not needed headless.
need_pkgs=()
have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }
have_lib 'libusb-1.0.so.0' || need_pkgs+=(libusb-1.0-0)
have_lib 'libgomp.so.1' || need_pkgs+=(libgomp1)
if ((${#need_pkgs[@]})); then
    echo "[bootstrap] installing system packages: ${need_pkgs[*]}"
    SUDO=""
    if [ "$(id -u)" != 0 ]; then
        if command -v sudo >/dev/null; then SUDO="sudo"; else
            echo "[bootstrap] ERROR: need root (or sudo) to install ${need_pkgs[*]}:" >&2
            echo "            apt-get install -y ${need_pkgs[*]}" >&2
            exit 1
        fi
    fi
    if command -v apt-get >/dev/null; then
        $SUDO apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_pkgs[@]}" >/dev/null
    else
        echo "[bootstrap] ERROR: no apt-get; install the libraries for ${need_pkgs[*]} by hand" >&2
        exit 1
    fi
fi

if [ ! -x "$VENV/bin/python" ]; then
    echo "[bootstrap] creating $VENV"
    "$PYTHON" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null
echo "[bootstrap] installing graphloc and its dependencies into $VENV (first time takes a few minutes)"
"$VENV/bin/python" -m pip install -q -e ".[test,live]"
# Fail here, with a clear message, rather than inside the first test that imports them.
"$VENV/bin/python" - <<'PY'
import importlib, sys
for mod in ("gtsam", "numpy", "scipy", "cv2", "open3d", "kiss_icp", "matplotlib", "tqdm", "pydantic"):
    try:
        importlib.import_module(mod)
    except Exception as exc:  # noqa: BLE001 - report every broken import by name
        sys.exit(f"[bootstrap] ERROR: `import {mod}` failed after install: {exc}")
print("[bootstrap] environment ready")
PY
