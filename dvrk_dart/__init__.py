"""dvrk_dart: a DART simulator of the dVRK Patient Side Manipulator, validated
against the identified dynamic model (Wang et al. 2019) and the real robot."""

__version__ = "0.1.0"

import os as _os

# One BLAS thread per process unless the user says otherwise: the project's
# linear algebra is many small problems (harmonic projections, 49-column fits)
# run by several worker processes, where threaded BLAS only fights itself (an
# identification took 25x longer with two threads per process on a loaded
# 2-core machine). Set before numpy is first imported.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_name, "1")
