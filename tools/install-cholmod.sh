#!/bin/sh
# Best-effort install of CHOLMOD (scikit-sparse, the [fast] extra) into the virtual environment $1/..
# Needs Debian's libsuitesparse-dev; installs it when running as root with apt-get available.
# Without it hamsa still works and falls back to SciPy's SuperLU (slower), saying so once.
# Debian's CHOLMOD calls whichever libblas.so.3 the system selects: the unoptimized reference BLAS unless an
# optimized one is installed, so the script also installs OpenBLAS (libopenblas0-pthread) when it can.
BIN="$1"
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ] && ! ls /usr/lib/*/openblas-pthread/libblas.so.3 >/dev/null 2>&1; then
    (apt-get install -y -qq libopenblas0-pthread >/dev/null 2>&1 \
        || (apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq libopenblas0-pthread >/dev/null 2>&1)) \
        && echo "OpenBLAS installed (the BLAS behind CHOLMOD's supernodal kernels)" \
        || echo "notice: could not install OpenBLAS; CHOLMOD uses the system's default BLAS (hamsa config shows which)"
fi
# threadpoolctl: hamsa holds CHOLMOD's BLAS to one thread in the supernodal kernel's solves
"$BIN/pip" install -q "threadpoolctl>=3" >/dev/null 2>&1 || echo "notice: could not install threadpoolctl; CHOLMOD stays simplicial"
if "$BIN/python" -c "import sksparse.cholmod" 2>/dev/null; then
    exit 0
fi
if [ ! -f /usr/include/suitesparse/cholmod.h ] && command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "installing libsuitesparse-dev (for CHOLMOD) ..."
    (apt-get install -y -qq libsuitesparse-dev >/dev/null 2>&1 \
        || (apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq libsuitesparse-dev >/dev/null 2>&1)) \
        || echo "could not install libsuitesparse-dev"
fi
# scikit-sparse 0.5 does not build against Debian 12's SuiteSparse 5.12; 0.4.x does.
if "$BIN/pip" install -q "scikit-sparse>=0.4.12,<0.5" >/dev/null 2>&1; then
    echo "CHOLMOD (scikit-sparse) installed"
else
    echo "notice: CHOLMOD (scikit-sparse) could not be built; hamsa will use SciPy's SuperLU (slower)."
fi
exit 0
