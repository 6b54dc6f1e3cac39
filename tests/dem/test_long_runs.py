"""A long run in one kernel call does not use up the stack.

Numba 0.56 keeps the schedule of each parallel loop on the stack of the function that runs
it until that function returns (numba issue 9029). With the step's two parallel loops
inside ``fused.advance``'s loop of steps, the stack grew ≈ 120 bytes a step and a run of
two spheres at rest, whose lists never need a rebuild (so the kernel never returns),
crashed after 50,000–100,000 steps. The regions are now functions of their own. The run
below takes 60,000 steps in one call under a 4 MiB stack: ≈ 7 MB of growth before."""
import os
import resource
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
STACK = 4 * 1024 * 1024
SCENE = """
from de_domain import Engine, Material, Particles, PlaneWall
mat = [Material(density=2650, young=5e7, friction=0.5, restitution=0.5)]
p = Particles.from_spheres([[0, 0, 0.001], [0.003, 0, 0.0008]], [0.001, 0.0008], materials=mat)
e = Engine(p, mat, walls=[PlaneWall((0, 0, 0), (0, 0, 1))], gravity=(0, 0, -9.81), local_damping=0.3)
e.run(60000)
print(e.step_count, e.neighbors.n_builds)
"""


def _small_stack():
    resource.setrlimit(resource.RLIMIT_STACK, (STACK, STACK))


def test_sixty_thousand_steps_in_one_kernel_call_fit_a_small_stack():
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_NUM_THREADS="2")
    out = subprocess.run([sys.executable, "-c", SCENE], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=600, preexec_fn=_small_stack)
    assert out.returncode == 0, f"exit {out.returncode}: {out.stderr[-2000:]}"
    steps, builds = map(int, out.stdout.split())
    assert steps == 60000 and builds == 1  # one call of the kernel: the lists never rebuilt
