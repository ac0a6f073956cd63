#!/usr/bin/env bash
# CI (issue 22): the fast suite where ROS users are. setup.cfg promises Python 3.10-3.12 with
# numpy >= 1.21 and scipy >= 1.8; a ROS user's numpy, scipy and matplotlib are the ones their
# distro installs through apt. Each combination gets a fresh virtual environment with the
# project installed by pip as such a user would, the distro's versions pinned by a constraints
# file (.ci/constraints-*.txt), then the README's test command against that installation.
# The slow statistical set runs on the main combination only (.ci/run).
#
# Pythons: pyenv's (as on the CI image) unless HUMBLE_PYTHON / JAZZY_PYTHON name others. A
# missing interpreter fails CI rather than skipping a combination silently.
set -euo pipefail
cd "$(dirname "$0")/.."
pyenv_root="${PYENV_ROOT:-$HOME/.pyenv}"

# combination NAME PYTHON CONSTRAINTS EXTRAS
combination() {
    local name="$1" python="$2" constraints="$3" extras="$4"
    if [[ ! -x "$python" ]]; then
        echo "python-matrix: $name: no interpreter at $python" >&2
        return 1
    fi
    local start=$SECONDS venv
    venv="$(mktemp -d)/venv"
    "$python" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --upgrade pip
    "$venv/bin/python" -m pip install --quiet --constraint "$constraints" ".[$extras]"
    "$venv/bin/python" -m pip check
    local installed=$SECONDS
    local versions
    versions="$("$venv/bin/python" -c 'import platform, numpy, scipy, matplotlib
import numba
print(f"Python {platform.python_version()}, numpy {numpy.__version__}, scipy {scipy.__version__}, matplotlib {matplotlib.__version__}, numba {numba.__version__}")')"
    echo "python-matrix: $name: $versions, extras [$extras]"
    # The venv's pytest script, not python -m pytest: the repository root stays off sys.path,
    # so the tests import the installed package (its package data included).
    "$venv/bin/pytest" -q -p no:cacheprovider
    echo "python-matrix: $name: passed; install $((installed - start)) s, tests $((SECONDS - installed)) s"
}

# Usage: python_matrix.sh [humble|jazzy ...] (default: both, one after the other).
combinations=("$@")
if [[ ${#combinations[@]} -eq 0 ]]; then combinations=(humble jazzy); fi
for name in "${combinations[@]}"; do
    case "$name" in
    # ROS 2 Humble (Ubuntu 22.04): Python 3.10. pin's wheels need numpy >= 1.26: no pinocchio extra.
    # fast: the numba the distro ships (pinned in the constraints), for the backend equality tests.
    humble) combination humble "${HUMBLE_PYTHON:-$pyenv_root/versions/3.10.13/bin/python}" .ci/constraints-humble.txt test,fast ;;
    # ROS 2 Jazzy (Ubuntu 24.04): Python 3.12.
    jazzy) combination jazzy "${JAZZY_PYTHON:-$pyenv_root/versions/3.12.1/bin/python}" .ci/constraints-jazzy.txt test,pinocchio,fast ;;
    *) echo "python-matrix: unknown combination '$name' (humble, jazzy)" >&2; exit 2 ;;
    esac
done
