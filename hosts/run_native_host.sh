#!/bin/sh
# Launcher that puts libpython into a native (non-Python) FMI host, for those who prefer to
# choose the interpreter this way. No host needs it any more: the project's FMUs find a Python
# themselves (their loader, src/piezo_fmu/build/loader; see docs/simulators.md). It remains for
# other pythonfmu FMUs, whose binary calls the Python C API but does not link libpython and so
# loads only into a process that has libpython's symbols.
#
#   PYTHON=.venv/bin/python hosts/run_native_host.sh PROGRAM [ARGS...]
#
# For the Python interpreter $PYTHON (default: python3 on PATH) whose packages the FMU is to use
# (numpy), it sets
#
#   LD_PRELOAD=<libpython of $PYTHON>     the shared libpython, e.g. .../lib/libpython3.11.so.1.0
#   PYTHONHOME=<sys.base_prefix>          where the embedded interpreter finds its standard library
#   PYTHONPATH=<site-packages of $PYTHON> where it finds numpy (a venv's own packages)
#
# and the project's FMUs then use that interpreter as they use a Python host's. The Python must
# be built with --enable-shared (Debian's python3 is; so are pyenv builds made with
# PYTHON_CONFIGURE_OPTS=--enable-shared, as on this project's machines). The launcher exits with
# status 127 and a message when it cannot find the shared library.
set -eu

if [ "$#" -lt 1 ]; then
    echo "usage: PYTHON=/path/to/python $0 PROGRAM [ARGS...]" >&2
    exit 2
fi

PYTHON=${PYTHON:-python3}

settings=$("$PYTHON" - <<'EOF'
import os
import sys
import sysconfig

libdir = sysconfig.get_config_var("LIBDIR") or ""
names = [sysconfig.get_config_var("INSTSONAME"), sysconfig.get_config_var("LDLIBRARY")]
candidates = [os.path.join(libdir, n) for n in names if n and ".so" in n]
multiarch = sysconfig.get_config_var("MULTIARCH")
if multiarch:
    candidates += [os.path.join("/usr/lib", multiarch, n) for n in names if n and ".so" in n]
library = next((c for c in candidates if os.path.isfile(c)), "")
print(library)
print(sys.base_prefix)
print(os.pathsep.join(p for p in sys.path if p.endswith("site-packages") and os.path.isdir(p)))
EOF
)

libpython=$(printf '%s\n' "$settings" | sed -n 1p)
pythonhome=$(printf '%s\n' "$settings" | sed -n 2p)
sitepackages=$(printf '%s\n' "$settings" | sed -n 3p)

if [ -z "$libpython" ]; then
    echo "$0: $PYTHON has no shared libpython (build it with --enable-shared, or use Debian's python3)" >&2
    exit 127
fi

LD_PRELOAD="$libpython${LD_PRELOAD:+ $LD_PRELOAD}"
PYTHONHOME="$pythonhome"
PYTHONPATH="$sitepackages${PYTHONPATH:+:$PYTHONPATH}"
export LD_PRELOAD PYTHONHOME PYTHONPATH
exec "$@"
