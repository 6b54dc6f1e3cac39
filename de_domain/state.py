"""The state the compiled step kernels read and write, grouped by what it describes.

The kernels of :mod:`de_domain.fused`, :mod:`de_domain.walls` and
:mod:`de_domain.integrate` take these named tuples of arrays instead of long
positional lists (jax-md hands its integrators a namedtuple of arrays the same way).
Why named tuples and not ``jitclass``/``structref``: Numba compiles a namedtuple of
arrays as a plain struct of array views (no reference-counted object, no boxing
cost per attribute read), its fields are read as ``particles.pos`` in compiled and
Python code alike, it is built in a microsecond from the arrays the Python objects
already own (nothing is copied), and it is cached by ``njit(cache=True)`` like any
other argument type. A field added here is added in one place; the kernels that do
not read it need no change, and two arrays of the same type can no longer be
swapped by position. A tuple has at most 15 fields: Numba 0.56 on Python 3.11 cannot
hand a namedtuple of 16 or more fields to a parallel loop (it rebuilds it with
keyword arguments, numba issue 8900).

Slots of the small result arrays have names (``BOOK_*``, ``CLOCK_*``, ``E_*``), the
way the pair parameters have (``materials.PAIR_*``).
"""
from collections import namedtuple

StepSettings = namedtuple("StepSettings", [
    "law",               # contact_laws.LINEAR or HERTZ
    "dt",                # time step [s]
    "gravity",           # (3,) [m/s²]
    "local_damping",     # α_b, Cundall local damping (docs/design.md §2.13)
    "viscous_damping",   # α_v [1/s]
    "has_constraints",   # any blocked or prescribed DOF
    "rolling",           # any material pair with rolling stiffness β_r > 0 (rolling moments stored)
    "in_order",          # the particle arrays are the spatially sorted copies (index = perm position)
    "skin",              # Verlet skin [m]
])
"""Scalars of one run: the same for every particle and step."""

ParticleArrays = namedtuple("ParticleArrays", [
    "pos", "vel", "accel", "angvel",            # (n, 3): x, v^{n−½}, last (v^{n+½} − v^{n−½})/Δt, ω^{n−½}
    "radius", "mass", "inertia", "material",    # (n,)
    "blocked", "prescribed",                    # (n, 6) bool: x y z rx ry rz
    "prescribed_velocity",                      # (n, 6)
    "force", "torque",                          # (n, 3): resultant of the last step
    "ref_pos",                                  # (n, 3): positions at the last list build
    "ghost",                                    # (n,) bool: a copy of another rank's particle (not integrated)
])
"""Per-particle arrays, in the public order or as spatially sorted copies."""

ContactParameters = namedtuple("ContactParameters", [
    "young",        # (n_materials,) Young's modulus per material
    "pair_params",  # (n_materials, n_materials, N_PAIR) mixed pair values (materials.PAIR_*)
])

PairList = namedtuple("PairList", [
    "perm",           # (n,) particle index of each perm position s (spatial order)
    "i_start",        # (n+1,) CSR: pairs of perm[s] as i-side
    "pair_js",        # (m,) perm position of each pair's j
    "j_start",        # (n+1,) CSR: j-side slots of perm[s]
    "j_slot",         # (m,) j-side slot of each pair
    "tangential",     # (m, 3) tangential spring force (history)
    "rolling_moment",  # (m, 3) rolling moment on i (history; (0, 3) without rolling)
    "j_record",       # (m, 6) force and torque each pair puts on its j, in j-side order
    "overlap",        # (m,) overlap of the last step (NaN: unknown; −1: apart now and last step)
])
"""Sphere–sphere half list with its contact history (neighbors module docstring)."""

PlaneWalls = namedtuple("PlaneWalls", [
    "point", "normal", "velocity",  # (n_walls, 3)
    "material",                     # (n_walls,)
    "ref_point",                    # (n_walls, 3) points at the last list build
    "start",                        # (n+1,) CSR over perm positions: candidates of perm[s]
    "wall",                         # (c,) wall index of each candidate
    "history",                      # (c, 6) tangential spring (3), rolling moment (3)
    "normal_force",                 # (c,) normal force of the last step
    "force",                        # (c, 3) force on the particle of the last step
])
"""Infinite plane walls and the sparse sphere–wall candidates (walls within r + skin)."""

FacetMeshes = namedtuple("FacetMeshes", [
    "vertices", "vertex_velocity",         # (nv, 3), all meshes concatenated
    "triangles", "triangle_edges",         # (nt, 3) vertex and edge ids
    "triangle_material", "triangle_mesh",  # (nt,)
    "vertex_force", "vertex_impulse",      # (nv, 3)
    "ref_vertices",                        # (nv, 3) vertices at the last list build
])
"""Triangle facet meshes, concatenated."""

FacetCandidates = namedtuple("FacetCandidates", [
    "particle_index",  # (n,) public particle index of each perm position (this CSR's index)
    "start",           # (n+1,) CSR over public particle indices
    "triangle",        # (c,) candidate triangle
    "history",         # (c, 6) tangential spring (3), rolling moment (3)
    "active",          # (c,) bool: in contact this step
    "force",           # (c, 3) force on the particle
    "barycentric",     # (c, 3) weights of the closest point
])
"""Sphere–triangle candidates (triangles within r + skin at the list build)."""

ClumpArrays = namedtuple("ClumpArrays", [
    "member_of",      # (n,) per particle row of the kernel: its clump, or −1 for a free sphere
    "pos", "vel",     # (nc, 3): centre of mass xⁿ, v^{n−½}
    "quat",           # (nc, 4): orientation qⁿ, body (principal) frame → space (de_domain.rigid)
    "angmom",         # (nc, 3): angular momentum L^{n−½}, space frame
    "mass",           # (nc,)
    "moments",        # (nc, 3): principal moments of inertia I1 ≤ I2 ≤ I3
    "member_start",   # (nc+1,) CSR: members of clump c are member_row[member_start[c]:member_start[c+1]]
    "member_row",     # (m,) particle row of each member of the kernel (template order); −1: another rank owns it
    "member_body",    # (m, 3) member centre in the body frame
    "force", "torque",  # (nc, 3): resultant on the clump of the last step (contacts + gravity), about its centre
    "member_load",    # (m, MEMBER_COLUMNS): this step's contact force, torque and position of each member
    "active",         # (na,) ascending: the clumps this process advances (all of them on one process)
    "booked",         # (nc,) bool: this process books clump c's energy terms (one rank per clump)
])
"""Rigid clumps of member spheres (docs/design.md §2.19): the members are particles for the
contacts; the clumps carry their motion (:func:`de_domain.fused.integrate_clumps`), from the
members' loads collected into ``member_load`` (:func:`de_domain.fused.collect_member_loads`).
Over MPI ranks a rank advances the clumps it owns a member of (``active``), with the loads of
their members on other ranks gathered between the two, and places the members it owns."""

# Columns of ClumpArrays.member_load: force (3), torque (3), position (3)
MEMBER_FORCE = 0
MEMBER_TORQUE = 3
MEMBER_POSITION = 6
MEMBER_COLUMNS = 9

StepBuffers = namedtuple("StepBuffers", [
    "contact",        # (nb, N_CONTACT_ENERGY): each pair block's contact terms
    "boundary",       # (nb, N_WALL_ENERGY + N_INTEGRATION): each particle block's boundary, then integration terms
    "shift",          # (nb,): each particle block's largest squared displacement since the last list build
    "clump_terms",    # (nc, N_INTEGRATION): each clump's integration terms
    "clump_shift",    # (nc,): each clump's members' largest squared displacement since the last list build
    "contact_sum",    # (N_CONTACT_ENERGY,), (N_WALL_ENERGY,), (N_INTEGRATION,): the step's sums over the blocks
    "boundary_sum",
    "integration_sum",
])
"""Per-step sums of one step's parallel work items, added in a fixed order afterwards
(:func:`de_domain.fused.step_forces`, :func:`de_domain.fused.finish_step`)."""

# Energy books (Engine.energy), one float64 array: the state terms at tⁿ, then the
# rate terms accumulated, of the first recorded step and of the last (trapezoidal rule).
N_STATE = 6   # engine.STATE_TERMS
N_RATE = 5    # engine.RATE_TERMS
BOOK_STATE = 0
BOOK_ACCUMULATED = BOOK_STATE + N_STATE
BOOK_FIRST = BOOK_ACCUMULATED + N_RATE
BOOK_LAST = BOOK_FIRST + N_RATE
BOOK_INITIAL_TOTAL = BOOK_LAST + N_RATE
BOOK_INITIALISED = BOOK_INITIAL_TOTAL + 1
N_BOOKS = BOOK_INITIALISED + 1

# The run clock handed to fused.advance: [time, steps done, the owned particles' largest
# displacement since the last list build after the last step (< 0: not known)]
CLOCK_TIME = 0
CLOCK_STEPS = 1
CLOCK_PARTICLE_SHIFT = 2
N_CLOCK = 3

# Contact energy terms of one step, as summed per block: stored elastic energy at tⁿ,
# then this step's dissipation (contact_laws.ContactEnergy has the same order).
E_NORMAL = 0
E_TANGENTIAL = 1
E_ROLLING = 2
E_FRICTION = 3
E_DAMPING = 4
N_CONTACT_ENERGY = 5

# Boundary terms per block (plane walls and facets): the work they do on the
# particles in this step, then the contact terms above.
W_WORK = 0
W_CONTACT = 1
N_WALL_ENERGY = W_CONTACT + N_CONTACT_ENERGY

# Integration terms per block (integrate.integrate_block).
I_KINETIC_TRANSLATIONAL = 0
I_KINETIC_ROTATIONAL = 1
I_GRAVITY = 2
I_BACKGROUND_DAMPING = 3
I_BOUNDARY_WORK = 4
N_INTEGRATION = 5
