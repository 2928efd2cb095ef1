#!/usr/bin/env bash
# Sourced by the scripts/*-venv.sh scripts: `python_venv DIR CHECK PACKAGE...`
# makes sure `DIR/bin/python -c CHECK` succeeds, else creates the virtual
# environment DIR (on a bare Debian after installing python3-venv, the only
# system-wide install) and pip-installs PACKAGE... into it.
python_venv() {
    local dir="$1" check="$2"
    shift 2
    if ! "$dir/bin/python" -c "$check" >/dev/null 2>&1; then
        echo "== installing $* into $dir"
        if ! python3 -m venv "$dir" >/dev/null 2>&1; then
            apt-get update -qq && apt-get install -y -qq python3-venv
            python3 -m venv "$dir"
        fi
        "$dir/bin/pip" install --quiet --disable-pip-version-check "$@"
    fi
}
