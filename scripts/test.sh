#!/usr/bin/env bash
# The test command: set-up (idempotent) then the whole suite, headless (EGL) and offline; then a fast subset whose
# expectations must hold on any host (exact solver results, chapter-5 trials, the physics episode) once more under
# each of two other OpenBLAS kernels that every x86-64 host of this kind runs, so that a value recorded on one
# machine's kernel fails here instead of on the next machine.
# With arguments, only pytest with those arguments (e.g. one file, -k, -x): the kernel re-runs are the no-argument
# command's.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
export MUJOCO_GL=egl PYOPENGL_PLATFORM=egl
if [ "$#" -gt 0 ]; then
    exec .venv/bin/python -m pytest -q "$@"
fi
# One pytest worker per core (pytest-xdist); TEST_WORKERS=1 runs the suite in one process.
WORKERS=(-n "${TEST_WORKERS:-auto}")
.venv/bin/python -m pytest -q "${WORKERS[@]}"
KERNEL_SUBSET=(
    tests/decision/test_solver_backup.py
    tests/decision/test_solver_golden.py
    tests/decision/test_solver_bounds.py::test_no_expand_reproduces_the_fixed_set_solver
    tests/decision/test_pomdp_solvers.py
    tests/arenas/test_pursuit_pairs_ablation.py
    tests/experiments/test_chapter5_trials.py
    tests/envs/test_toxic_waste_env.py::test_a_hotspot_episode_succeeds
)
for kernel in Haswell Sandybridge; do
    echo "== host-independence subset under OPENBLAS_CORETYPE=$kernel"
    OPENBLAS_CORETYPE="$kernel" .venv/bin/python -m pytest -q "${WORKERS[@]}" "${KERNEL_SUBSET[@]}"
done
