# Sourced (from the repository root) by run.sh and dam_break.sh: sets VENV to PySPH 1.0b2's virtual
# environment (target/pysph-venv, or $PAIRSUM_PYSPH_VENV) and installs PySPH there the first time,
# which takes a few minutes (pip builds PySPH's Cython extensions from its source release unless
# pip's cache already holds the wheel).
VENV=${PAIRSUM_PYSPH_VENV:-target/pysph-venv}

if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import pysph' 2>/dev/null; then
    echo "installing PySPH 1.0b2 into $VENV ..." >&2
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q --upgrade pip setuptools wheel
    "$VENV/bin/pip" install -q 'pysph==1.0b2'
fi
