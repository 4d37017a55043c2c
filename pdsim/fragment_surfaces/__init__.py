"""Renderable fracture surfaces: one closed, outward-oriented triangle shell per fragment of a body.

Method
------
The input surface mesh is kept in rest space. When the fragment labels change
(:meth:`FragmentSurfaces.update_topology`) each fragment's rest-space shape is rebuilt as ``region(fragment) ∩ input
mesh`` with manifold3d's exact mesh booleans, where the fragments' regions partition space exactly. Outer faces are
therefore pieces of the input triangles (same positions) and crack faces are pieces of the region boundaries. The
steps, and the module of each:

1. **Label grid** (regions.py): a grid of the particle spacing h, aligned with the particles, labelled by the
   particles' fragments (a vote of the nearest particles where no particle sits).
2. **Partition of space** (regions.py): multi-label marching tetrahedra over the Freudenthal triangulation of the
   grid; every interface point is keyed by the simplex it lies on, so neighbouring regions share their triangles and
   each region's boundary is a closed 2-manifold.
3. **Smooth cracks** (regions.py): crack points slide along their grid edges onto planes fitted to the staircase
   between two fragments (``crack_smoothing``); 3b: off the lattice, crack points that graze the input surface move
   off it within their simplex.
3a. **Refined input** (booleans.py): the input surface refined to edges of about h (planes stay planes).
4. **Clip** (booleans.py): ``region ∩ input surface`` per region; input faces are outer faces, the rest crack faces.
5. **Shared complex** (booleans.py): coincident vertices of all shells merged and each crack triangulated once, so
   the two sides of a crack use the very same triangles.
6. **Slivers** (cleanup.py): edge collapses, edge flips and vertex moves on the shared complex that keep every shell
   closed and every outer face on the input surface. A rebuild first applies the last clean-up's edits wherever the
   complex around them is unchanged (edits.py), so the clean-up works where the regions changed.
7. **Damage** (surfaces.py): particles whose damage reaches ``damage_threshold`` (a peridynamic body's
   ``Material.chip_damage``) become chips. By default (``chip_shape="cube"``) all chips together make one region of the
   partition that gets no shell, so the fragments get crack faces where the chips were, and each chip is drawn as a cube
   of edge 0.8 h around its particle; ``chip_shape="cell"`` makes each chip a region of its own, clipped and cleaned
   with the fragments.
8. **Motion** (embedding.py): each shell vertex follows its region's particles: the region's best-fit rigid motion
   plus moving-least-squares interpolated residuals, a sparse product per frame. Vertex velocities are the time
   derivative of this map, ``v_v = c' + w x R (X_v - Xc) + sum_k phi_vk (v_k - c' - w x R (X_k - Xc))`` with the mean
   velocity c' and the best-fit angular velocity w of the region's particles (surfaces.py).
9. **Drawn surface** (drawn.py): each frame, edges drawn longer than 3 h split at their rest-space midpoints (embedded
   like every vertex) and slivers made by the motion flipped, relaxed and merged away.

USD: one ``UsdGeom.Mesh`` per body at ``/World/<body>_surface`` holds every shell. It carries the uniform (per-face)
int primvars ``fragment`` (the fragment label; chips carry their particle's fragment) and ``crack`` (1 on crack
faces, 0 on faces of the input surface). Points, vertex velocities and extent are written every frame;
``faceVertexCounts``, ``faceVertexIndices`` and the two primvars only on the first frame and on frames where the
regions changed.

Cost: a rebuild is one boolean per region whose geometry changed since the last rebuild (the others reuse their
clip), each against the cut of the input near the region (booleans.py: ``InputCuts``), plus the clean-up within two
rings of where the complex changed; chips drawn as cubes cost neither (the faces between neighbouring chips' cells
were most of the crack triangles of a crumbling wall); a frame's vertex update is a rigid fit per shell and a
sparse product. In a run
the rebuild and the drawn surface of frame N are built on the run's surface thread while frame N + 1 simulates
(pdsim/frame_worker.py).
"""

from .cleanup import shells_closed, triangle_angles
from .drawn import DrawnSurface
from .regions import LatticeGrid, build_lattice_grid, partition_regions
from .surfaces import DAMAGE_THRESHOLD, FragmentSurfaces, surface_states, with_states

__all__ = [
    "DAMAGE_THRESHOLD",
    "DrawnSurface",
    "FragmentSurfaces",
    "LatticeGrid",
    "build_lattice_grid",
    "partition_regions",
    "shells_closed",
    "surface_states",
    "triangle_angles",
    "with_states",
]
