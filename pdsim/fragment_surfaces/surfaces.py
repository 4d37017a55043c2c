"""The fragment surfaces of one body (:class:`FragmentSurfaces`): their rebuild when the regions change (steps
1-7 of the method in :mod:`pdsim.fragment_surfaces`), their motion with the particles (step 8) and the surface drawn
each frame (step 9).

Regions (step 7) are the fragments (connected components of live bonds), except that a particle whose damage reaches
``damage_threshold`` (default 0.5: about 0.38 next to a clean crack through the bulk, so clean cracks still show
through the fragments) becomes a chip of its own. It separates from its neighbours in the frame it loses that share
of its bonds, so a hole through a wall shows as soon as the damage crosses the wall, not when the last bond joining
the debris breaks. How a chip is drawn (``chip_shape``):

- ``"cube"`` (default): the chips together are one region of the partition that gets no shell, so the fragments'
  shells get crack faces where chips were (the crack smoothing rounds that hole like any crack), and each chip is a
  cube of edge 0.8 h (``CHIP_EDGE``) centred on its particle's rest position that translates with it, turned by a
  fixed turn of its own (so that chips side by side read as rubble, not as blocks lined up with the particles'
  lattice) and kept within the input; a cube face whose centre lies at the input surface (or outside it) is an outer
  face, the others crack faces.
- ``"cell"``: each chip is a region of its own, clipped by the input and cleaned with the fragments' shells.

The cubes keep the look (a crumbling wall's chips were cells of about a spacing) and drop the cost: next to each
other, chips' cells share crack faces that the clean-up must coarsen at every rebuild, most of a crumbling body's
crack triangles (docs/benchmarks.md, "Chips drawn as cubes").
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..geometry import SolidShape
from ..materials import CHIP_DAMAGE
from ..output.views import MeshView
from .booleans import InputCuts, clip_regions, plane_groups, refine_surface, shared_complex
from .drawn import DrawnSurface, drawn_surface
from .embedding import ShellEmbedding, rigid_fit
from .regions import LatticeGrid, build_lattice_grid, closest_points, partition_regions, signed_distances
from .tiles import TiledCleanup

__all__ = ["DAMAGE_THRESHOLD", "FragmentSurfaces", "surface_states", "with_states"]

# particles with at least this damage become chips of their own (step 7 of the method) unless a body's material
# says otherwise (Material.chip_damage)
DAMAGE_THRESHOLD = CHIP_DAMAGE
CHIP_SHAPES = ("cube", "cell")  # FragmentSurfaces(chip_shape=)
# the 12 outward triangles of the unit cube whose corner i has the offsets (bits of i: x, y, z) in {-1/2, 1/2}^3
_CUBE_CORNERS = np.array([[(i >> 0) & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=np.float64) - 0.5
_CUBE_TRIANGLES = np.array(
    [[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
     [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]],
    dtype=np.int64,
)  # fmt: skip
CHIP_OUTER_DEPTH = 0.25  # a chip cube's face whose centre lies less than this many spacings inside is an outer face
# edge of a chip's cube [spacings]: its volume, 0.51 h^3, about that of the hole chips leave in their fragment (the
# crack smoothing rounds their cells: 0.55 h^3 per chip of a 3 x 3 x 3 block), and the hole's crack faces show
# between neighbouring chips
CHIP_EDGE = 0.8
CHIP_TURN_SEED = 20261205  # the chips' fixed turns (_chip_rotations)


def _chip_rotations(n: int) -> np.ndarray:
    """[n, 3, 3] rotation matrices, one per particle, uniformly distributed and fixed: row i of normal draws of a
    generator seeded with CHIP_TURN_SEED, normalised to a quaternion (the same turn for particle i whatever n is). A
    chip's cube is turned by its particle's, so chips side by side do not line up with the particles' lattice."""
    q = np.random.default_rng(CHIP_TURN_SEED).normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
        ],
        axis=1,
    )


class FragmentSurfaces:
    """Closed, outward-oriented triangle shells of the fragments of one body, and their motion with the particles.

    See :mod:`pdsim.fragment_surfaces` for the method.

    Args:
        shape: the body's input surface in rest space (closed, outward oriented).
        rest_positions: particle rest positions [m], shape [n, 3], in the order of the labels and positions passed
            later (the body's sorted order).
        spacing: particle lattice spacing h [m].
        body_name: body label; the USD mesh is ``/World/<body_name>_surface``.
        crack_smoothing: how far crack points may slide from grid-edge midpoints, in [0, 0.45] of an edge (0: no
            smoothing, lattice-stepped cracks).
        simplify: if > 0, each clipped shell is simplified by manifold3d (edge collapses that move the surface by at
            most ``simplify * spacing``); about 0.05 halves the triangle count of crack-rich shells. The two sides of
            a crack are then simplified independently and match only within that tolerance, and the sliver clean-up
            is skipped; 0 (default) keeps the shared, cleaned complex.
        refine: refine the input surface to edges of about one spacing, so that an unbroken surface bends with
            the particles (default: True, unless ``simplify`` is set; False keeps the input triangles).
        damage_threshold: particles whose damage reaches this value become chips of their own, in (0, 1]; see
            :meth:`update_topology`.
        clean: remove slivers by edge collapses (default True).
        on_lattice: the particles are points of a lattice of this spacing (default True), so that those sitting on
            grid vertices label them; False labels every grid vertex by the vote of its nearest particles (particles
            anywhere, possibly coinciding: the vertices of a cracked FEM mesh, see :func:`build_lattice_grid`).
        device: Warp device of the one-off grid-near-mesh query.
        reuse: a rebuild takes the previous rebuild's clip of every region whose geometry is unchanged, bit for bit
            (default True; the shells are the same either way, False clips every region again).
        carry_edits: with ``clean_tiles`` off, a rebuild takes the last sliver clean-up's edits wherever the
            complex around them is unchanged and cleans only the rest (default True;
            pdsim/fragment_surfaces/edits.py); False cleans the whole complex at every rebuild.
        clean_tiles: clean tile by tile (default False; pdsim/fragment_surfaces/tiles.py: a tile's result depends
            on its own raw triangles only and is taken from the last rebuild where those are unchanged, so nothing
            is carried across rebuilds or checkpoints); False: the whole complex, with or without ``carry_edits``.
        chip_shape: how a chip is drawn: ``"cube"`` (default), a cube of edge 0.8 h around its particle, the chips
            leaving a hole in the partition of space; ``"cell"``, its cell of the partition, clipped by the input
            and cleaned with the fragments' shells (see :meth:`update_topology`).

    Attributes:
        fragment_ids: fragment label of each shell (chips carry their particle's fragment label; several shells
            may share one), int shape [shell_count].
        rest_vertices: all shells' vertices in rest space [m], float64 shape [vertex_count, 3], shell after shell.
        faces: all shells' triangles, int32 shape [face_count, 3], indices into ``rest_vertices``.
        face_fragment: fragment label of each face, int32 shape [face_count].
        face_crack: 1 for crack faces, 0 for faces from the input surface, int32 shape [face_count].
        vertex_fragment: shell index (0..shell_count-1) of each vertex, int shape [vertex_count].
        version: number of topology rebuilds (0: the intact input mesh).
        rebuild_seconds: wall time of the last rebuild [s].
        clips_made: regions the last rebuild clipped (the others took the previous rebuild's clips).
        clean_record: the last clean-up's record (pdsim/fragment_surfaces/edits.py: complex_record; empty when none),
            or None when ``carry_edits`` is off or ``clean_tiles`` on.
    """

    def __init__(
        self,
        shape: SolidShape,
        rest_positions: np.ndarray,
        spacing: float,
        body_name: str,
        *,
        crack_smoothing: float = 0.45,
        simplify: float = 0.0,
        refine: bool | None = None,
        damage_threshold: float = DAMAGE_THRESHOLD,
        clean: bool = True,
        on_lattice: bool = True,
        device: str = "cpu",
        reuse: bool = True,
        carry_edits: bool = True,
        clean_tiles: bool = False,
        chip_shape: str = "cube",
    ):
        rest = np.asarray(rest_positions, dtype=np.float64)
        if rest.ndim != 2 or rest.shape[1] != 3 or rest.shape[0] == 0:
            raise ValueError(f"rest_positions must have shape [n, 3] with n > 0, got {list(rest.shape)}")
        if not (np.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing={spacing!r} must be a finite number > 0")
        if not 0.0 <= crack_smoothing <= 0.45:
            raise ValueError(f"crack_smoothing={crack_smoothing!r} must lie in [0, 0.45]")
        if not (np.isfinite(simplify) and 0.0 <= simplify <= 0.5):
            raise ValueError(f"simplify={simplify!r} must lie in [0, 0.5] (a fraction of the spacing)")
        if not (np.isfinite(damage_threshold) and 0.0 < damage_threshold <= 1.0):
            raise ValueError(f"damage_threshold={damage_threshold!r} must lie in (0, 1]")
        if chip_shape not in CHIP_SHAPES:
            raise ValueError(f"chip_shape={chip_shape!r} must be one of {', '.join(map(repr, CHIP_SHAPES))}")
        self.chip_shape = chip_shape
        self.shape = shape
        self.rest_positions = rest
        self.spacing = float(spacing)
        self.body_name = body_name
        self.crack_smoothing = float(crack_smoothing)
        self.simplify = float(simplify)
        self.damage_threshold = float(damage_threshold)
        self.clean = bool(clean)
        self.on_lattice = bool(on_lattice)
        self.version = 0
        self._key: np.ndarray | None = None
        self._view_faces: np.ndarray | None = None  # the faces of the last view, of rebuild _view_of, and their version
        self._view_of = -1
        self._view_version = 0
        self._cuts: InputCuts | None = None
        self._clips = {} if reuse else None  # the last rebuild's clips, by region (booleans.clip_regions)
        self.clips_made = 0
        self.clean_record = {} if carry_edits and not clean_tiles else None
        self._grid: LatticeGrid | None = None
        self._cubes = None  # _chip_cubes, made with the grid
        self.device = device
        self.rebuild_seconds = 0.0
        self.clean_failed = False
        v, f = np.asarray(shape.vertices, np.float64), np.asarray(shape.faces, np.int64)
        if refine is None:
            refine = self.simplify == 0.0
        if refine:
            self._surface = refine_surface(v, f, self.spacing)
        else:
            self._surface = (v, f, plane_groups(v, f))
        self._tiles = TiledCleanup(self._surface, self.spacing) if clean_tiles else None
        n = rest.shape[0]
        self._set_topology(np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64))

    @property
    def particle_count(self) -> int:
        return self.rest_positions.shape[0]

    @property
    def fragment_count(self) -> int:
        """Number of shells (fragments, and chips of damaged particles)."""
        return int(self.fragment_ids.shape[0])

    @property
    def meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per shell: (rest vertices [m] float64 [v_i, 3], triangles int32 [f_i, 3] indexing those vertices)."""
        out = []
        for k in range(self.fragment_count):
            v0, v1 = self._vertex_ranges[k], self._vertex_ranges[k + 1]
            f0, f1 = self._face_ranges[k], self._face_ranges[k + 1]
            out.append((self.rest_vertices[v0:v1], self.faces[f0:f1] - v0))
        return out

    # ------------------------------------------------------------------ topology

    def region_keys(self, labels, damage=None) -> np.ndarray:
        """Region of each particle, int64 [particle_count]: its fragment label, or ``-1 - index`` (a chip of its
        own) where ``damage`` reaches ``damage_threshold``."""
        labels = np.asarray(labels)
        if labels.shape != (self.particle_count,) or not np.issubdtype(labels.dtype, np.integer):
            raise ValueError(f"labels must be ints of shape [{self.particle_count}], got {labels.dtype} {labels.shape}")
        key = labels.astype(np.int64)
        if damage is not None:
            damage = np.asarray(damage, dtype=np.float64)
            if damage.shape != (self.particle_count,):
                raise ValueError(f"damage must have shape [{self.particle_count}], got {list(damage.shape)}")
            chip = damage >= self.damage_threshold
            key = np.where(chip, -1 - np.arange(self.particle_count), key)
        return key

    def update_topology(self, labels, damage=None) -> bool:
        """Rebuilds the shells if the regions changed since the last call.

        Regions are the fragments, except that every particle whose damage reaches ``damage_threshold`` is a region
        (a chip) of its own, drawn as ``chip_shape`` says: it separates from its neighbours as soon as it loses that
        share of its bonds, before the fragment splits, so a hole through a wall shows as soon as damage crosses the
        wall.

        Args:
            labels: fragment label per particle, int shape [particle_count] (any non-negative ints; equal labels
                mean the same fragment), e.g. ``FragmentTracker.body_labels(b)``.
            damage: damage per particle [-], shape [particle_count], or None (fragments only).

        Returns:
            True when the shells were rebuilt.
        """
        return self._update_key(self.region_keys(labels, damage), np.asarray(labels, dtype=np.int64))

    def _update_key(self, key: np.ndarray, labels: np.ndarray) -> bool:
        """Rebuilds the shells for region keys ``key`` (from :meth:`region_keys`) and fragment ``labels`` unless
        the keys are those of the last build; True when rebuilt."""
        if self._key is not None and np.array_equal(key, self._key):
            return False
        t0 = time.perf_counter()
        self._set_topology(key, labels)
        self.rebuild_seconds = time.perf_counter() - t0
        self.version += 1
        return True

    def checkpoint(self) -> dict:
        """What the next rebuild depends on beyond the particles' state: the last clean-up's record (arrays; empty
        when none or when ``carry_edits`` is off). A run's checkpoint stores it, so that a resumed run rebuilds as
        the uninterrupted one does."""
        return {} if not self.clean_record else {k: v.copy() for k, v in self.clean_record.items()}

    def restore(self, state: dict) -> None:
        """Puts a :meth:`checkpoint` back (the object's other state is rebuilt at the next update)."""
        if self.clean_record is not None:
            self.clean_record.clear()
            self.clean_record.update({k: np.asarray(v) for k, v in state.items()})

    def _input_cuts(self) -> InputCuts:
        """The (refined) input surface as a manifold3d solid and its cuts by tiles, made once."""
        if self._cuts is None:
            self._cuts = InputCuts(self._surface, self.shape.name, self.spacing)
        return self._cuts

    def _set_topology(self, key: np.ndarray, labels: np.ndarray) -> None:
        ids, first, region = np.unique(key, return_index=True, return_inverse=True)
        region = region.reshape(-1)
        self._key = key.copy()
        k_count = ids.shape[0]
        if k_count == 1:  # intact: the (refined) input surface
            points, tri, tri_patch = self._surface
            tri_shell = np.zeros(len(tri), dtype=np.int64)
            tri_crack = np.zeros(len(tri), dtype=np.int32)
            shared = True
        elif self.chip_shape == "cube" and ids[0] < 0:
            points, tri, tri_shell, tri_crack, tri_patch, shared = self._complex_with_chip_cubes(region, ids, first)
        else:
            points, tri, tri_shell, tri_crack, tri_patch, shared = self._clipped_complex(region, k_count)
        self._split_shells(points, tri, tri_shell, tri_crack, tri_patch, labels[first], region, k_count, shared)
        self._build_interpolation()

    def _complex_with_chip_cubes(self, region: np.ndarray, ids: np.ndarray, first: np.ndarray):
        """The complex of :meth:`_clipped_complex` when some regions are chips (``ids`` [k] the sorted region keys,
        chips first, being negative; ``region`` [n] each particle's index into them; ``first`` [k] a particle of
        each): the fragments' shells from a partition in which all chips make one extra region that is then left
        out (the fragments get crack faces where chips were), and each chip a cube of edge 0.8 h around its particle's
        rest position (:meth:`_chip_cubes`: kept within the input), each face on a patch of its own, outer where
        it lies at the input surface and crack elsewhere. Same returns; shells numbered as ``ids``."""
        chips = int(np.searchsorted(ids, 0))
        fragments = len(ids) - chips
        if fragments:
            part = np.where(region < chips, fragments, region - chips)  # the chips: region ``fragments``, left out
            points, tri, shell, crack, patch, shared = self._clipped_complex(part, fragments + 1, left_out=fragments)
            shell = shell + chips
        else:
            points, tri = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
            shell, crack, patch = (np.zeros(0, dtype=np.int64),) * 3
            shared = True
        particle = first[:chips]
        corners, outer = self._chip_cubes()
        cube_points = corners[particle].reshape(-1, 3)
        cube_tri = (_CUBE_TRIANGLES[None] + len(points) + 8 * np.arange(chips)[:, None, None]).reshape(-1, 3)
        cube_shell = np.repeat(np.arange(chips), len(_CUBE_TRIANGLES))
        cube_face = np.tile(np.arange(len(_CUBE_TRIANGLES)) // 2, chips)  # the cube face of each triangle
        cube_crack = (~outer[particle[cube_shell], cube_face]).astype(np.int32)
        first_patch = int(patch.max()) + 1 if len(patch) else 0
        return (
            np.concatenate([points, cube_points]),
            np.concatenate([tri, cube_tri]),
            np.concatenate([shell, cube_shell]),
            np.concatenate([crack, cube_crack]).astype(np.int32),
            np.concatenate([patch, first_patch + 6 * cube_shell + cube_face]),
            shared,
        )

    def _chip_cubes(self):
        """Each particle's chip cube in rest space: (corners [m] float64 [particle_count, 8, 3]: the cube of edge
        CHIP_EDGE h centred on the particle and turned by its turn (_chip_rotations), every corner outside the input
        moved to its nearest point of the input surface, so the cube keeps within the input as the surface it replaces
        did; bool [particle_count, 6]: its faces, the triangle pairs of _CUBE_TRIANGLES (z-, z+, y-, y+, x-, x+ before
        the turn), whose centre then lies less than CHIP_OUTER_DEPTH spacings inside the input, drawn as outer
        faces). Warp queries, made with the label grid (in the thread that calls :meth:`deferred_view`)."""
        if self._cubes is None:
            n, h = self.particle_count, self.spacing
            turned = np.einsum("kj,nij->nki", _CUBE_CORNERS, _chip_rotations(n))  # [n, 8, 3]
            corners = (self.rest_positions[:, None, :] + CHIP_EDGE * h * turned).reshape(-1, 3)
            depth, nearest = closest_points(self.shape, corners, self.device)
            corners = np.where((depth > 0.0)[:, None], nearest, corners).reshape(n, 8, 3)
            quads = np.array([sorted(set(_CUBE_TRIANGLES[2 * f]) | set(_CUBE_TRIANGLES[2 * f + 1])) for f in range(6)])
            centres = corners[:, quads].mean(axis=2)  # [n, 6, 3]
            depth = signed_distances(self.shape, centres.reshape(-1, 3), self.device).reshape(n, 6)
            self._cubes = (corners, depth >= -CHIP_OUTER_DEPTH * h)
        return self._cubes

    def _lattice_grid(self) -> LatticeGrid:
        """The label grid (step 1), built on first use (a Warp query on ``device``)."""
        if self._grid is None:
            self._grid = build_lattice_grid(
                self.rest_positions, self.shape, self.spacing, device=self.device, on_lattice=self.on_lattice
            )
            if self.chip_shape == "cube":
                self._chip_cubes()
        return self._grid

    def _clipped_complex(self, region: np.ndarray, k_count: int, left_out: int | None = None):
        """All regions' shells as one complex (steps 1-6): the regions of :func:`partition_regions` over the label
        grid (built once), clipped by the input surface, joined and cleaned (:func:`shared_complex`). Returns (points
        [m] [p, 3], tri [f, 3], shell [f], crack flag [f], patch [f], shared); sets ``clean_failed`` when the
        clean-up ran. Region ``left_out`` (if any) takes part in the partition but gets no shell."""
        regions = partition_regions(self._lattice_grid(), region, crack_smoothing=self.crack_smoothing)
        if left_out is not None:
            regions[left_out] = (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64))
        pieces, self.clips_made = clip_regions(
            regions,
            self._input_cuts(),
            self._surface[2],
            self.spacing,
            self.simplify,
            self.body_name,
            reuse=self._clips,
        )
        *shells, clean_failed = shared_complex(
            pieces,
            k_count,
            self._surface,
            self.spacing,
            simplify=self.simplify,
            clean=self.clean,
            record=self.clean_record,
            tiles=self._tiles,
            left_out=left_out,
        )
        if clean_failed is not None:
            self.clean_failed = clean_failed
        return tuple(shells)

    def _split_shells(
        self, points, tri, tri_shell, tri_crack, tri_patch, region_fragment, region, k_count, shared
    ) -> None:
        """Per-shell vertex copies (shell after shell), faces, attributes and the particle -> shell map."""
        n_p = points.shape[0]
        order = np.argsort(tri_shell, kind="stable")
        tri, tri_shell, tri_crack = tri[order], tri_shell[order], tri_crack[order]
        self._face_patch = np.asarray(tri_patch, dtype=np.int64)[order]
        pair = np.unique(tri_shell[:, None] * n_p + tri)  # (shell, vertex), sorted by shell
        faces = np.searchsorted(pair, tri_shell[:, None] * n_p + tri)
        pair_shell = pair // n_p
        kept = np.unique(tri_shell)
        shell_index = -np.ones(k_count, dtype=np.int64)
        shell_index[kept] = np.arange(len(kept))
        self.fragment_ids = region_fragment[kept].astype(np.int32)
        self.rest_vertices = points[pair % n_p]
        self.faces = faces.astype(np.int32)
        self.face_fragment = region_fragment[tri_shell].astype(np.int32)
        self.face_crack = tri_crack.astype(np.int32)
        self.vertex_fragment = shell_index[pair_shell]
        self.shared = bool(shared)
        fcounts = np.bincount(shell_index[tri_shell], minlength=len(kept))
        vcounts = np.bincount(self.vertex_fragment, minlength=len(kept))
        self._vertex_ranges = np.concatenate([[0], np.cumsum(vcounts)])
        self._face_ranges = np.concatenate([[0], np.cumsum(fcounts)])
        self._face_shell = shell_index[tri_shell]
        self._particle_shell = shell_index[region]

    def _build_interpolation(self) -> None:
        """MLS shape functions of every vertex over the NEIGHBOR_COUNT nearest particles of its own shell, as a
        sparse matrix [vertex_count, particle_count]."""
        self._embedding = ShellEmbedding(self.rest_positions, self._particle_shell, self.shape.vertices, self.spacing)
        self._phi = self._embedding.shape_functions(self.rest_vertices, self.vertex_fragment)

    # ------------------------------------------------------------------ motion

    def _fit(self, x: np.ndarray):
        """Rigid fit per shell at particle positions x [m] [particle_count, 3]: (selected particles [s], their shell
        [s], rest centroids [g, 3], current centroids [g, 3], rotations [g, 3, 3])."""
        if x.shape != (self.particle_count, 3):
            raise ValueError(f"positions must have shape [{self.particle_count}, 3], got {list(x.shape)}")
        shell = self._particle_shell
        sel = np.flatnonzero(shell >= 0)
        rest_c, cur_c, rot = rigid_fit(self.rest_positions[sel], x[sel], shell[sel], self.fragment_count)
        return sel, shell[sel], rest_c, cur_c, rot

    def vertex_positions(self, positions, at=None) -> np.ndarray:
        """All shells' vertices at the current particle positions: ``x_v = T(X_v) + sum_k phi_vk r_k`` (rigid fit
        of the shell's particles plus the MLS-interpolated residuals, a sparse product).

        Args:
            positions: particle positions [m], shape [particle_count, 3].
            at: None (the shells' vertices), or other rest points embedded like them: (rest points [m] [q, 3],
                shell of each [q], their shape functions from :meth:`ShellEmbedding.shape_functions`).

        Returns:
            Vertex positions [m], float64 shape [vertex_count, 3] (shell after shell, as ``rest_vertices``).
        """
        rest_v, g, phi = (self.rest_vertices, self.vertex_fragment, self._phi) if at is None else at
        x = np.asarray(positions, dtype=np.float64)
        sel, group, rest_c, cur_c, rot = self._fit(x)
        rigid_p = cur_c[group] + np.einsum("nij,nj->ni", rot[group], self.rest_positions[sel] - rest_c[group])
        residual = np.zeros_like(x)
        residual[sel] = x[sel] - rigid_p
        out = cur_c[g] + np.einsum("nij,nj->ni", rot[g], rest_v - rest_c[g])
        return out + phi @ residual

    def vertex_velocities(self, positions, velocities, at=None) -> np.ndarray:
        """Vertex velocities [m/s], float64 [vertex_count, 3]: the time derivative of :meth:`vertex_positions`,
        ``v_v = c' + w x R (X_v - Xc) + sum_k phi_vk (v_k - c' - w x R (X_k - Xc))``, where c' is the mean velocity
        of the shell's particles and w their best-fit angular velocity (least squares, exact for a rigid motion).

        Args:
            positions: particle positions [m], [particle_count, 3]; velocities: particle velocities [m/s], same shape.
            at: as in :meth:`vertex_positions`.
        """
        rest_v, g, phi = (self.rest_vertices, self.vertex_fragment, self._phi) if at is None else at
        x = np.asarray(positions, dtype=np.float64)
        v = np.asarray(velocities, dtype=np.float64)
        if v.shape != x.shape:
            raise ValueError(f"velocities must have shape {list(x.shape)}, got {list(v.shape)}")
        sel, group, rest_c, cur_c, rot = self._fit(x)
        count = self.fragment_count
        n = np.maximum(np.bincount(group, minlength=count), 1).astype(np.float64)
        v_c = np.stack([np.bincount(group, v[sel, a], count) for a in range(3)], axis=1) / n[:, None]
        r = x[sel] - cur_c[group]
        dv = v[sel] - v_c[group]
        ang = np.cross(r, dv)
        ang_mom = np.stack([np.bincount(group, ang[:, a], count) for a in range(3)], axis=1)
        rr = np.einsum("ni,nj->nij", r, r).reshape(-1, 9)
        outer = np.stack([np.bincount(group, rr[:, j], count) for j in range(9)], axis=1).reshape(-1, 3, 3)
        inertia = np.trace(outer, axis1=1, axis2=2)[:, None, None] * np.eye(3) - outer
        scale = np.maximum(np.trace(inertia, axis1=1, axis2=2), 1e-300)[:, None, None]
        omega = np.einsum("gij,gj->gi", np.linalg.pinv(inertia / scale, rcond=1e-9), ang_mom / scale[:, :, 0])
        arm_p = np.einsum("nij,nj->ni", rot[group], self.rest_positions[sel] - rest_c[group])
        residual = np.zeros_like(v)
        residual[sel] = v[sel] - v_c[group] - np.cross(omega[group], arm_p)
        arm_v = np.einsum("nij,nj->ni", rot[g], rest_v - rest_c[g])
        return v_c[g] + np.cross(omega[g], arm_v) + phi @ residual

    def fragment_vertex_positions(self, positions) -> list[np.ndarray]:
        """Per shell, its vertices at the current particle positions: list of [v_i, 3] arrays [m]."""
        x = self.vertex_positions(positions)
        return [x[self._vertex_ranges[k] : self._vertex_ranges[k + 1]] for k in range(self.fragment_count)]

    # ------------------------------------------------------------------ output
    def deferred_view(self, positions, velocities=None, labels=None, damage=None) -> Callable[[], MeshView]:
        """What :meth:`update_topology` (when ``labels`` is given) and then :meth:`view` would return now, as a
        function to run later, possibly on another thread: it holds copies of ``positions`` [m], ``velocities``
        [m/s] (shape [particle_count, 3]), ``labels`` and ``damage`` ([particle_count]), so the caller may change
        its arrays meanwhile. The label grid, the one Warp query of a rebuild, is built here, in the calling thread,
        when the regions are more than one. Calls of the returned functions must run in the order they were made."""
        x = np.array(positions, dtype=np.float64)
        v = None if velocities is None else np.array(velocities, dtype=np.float64)
        key = None if labels is None else self.region_keys(labels, damage)
        frag = None if labels is None else np.array(labels, dtype=np.int64)
        if key is not None and self._grid is None and (key != key[0]).any():
            self._lattice_grid()

        def build() -> MeshView:
            if key is not None:
                self._update_key(key, frag)
            return self.view(x, v)

        return build

    def view(self, positions, velocities=None):
        """The surface as a MeshView ``<body>_surface`` for particle ``positions`` [m] (shape [particle_count, 3])
        and ``velocities`` [m/s] (same shape; None: no vertex velocities): the drawn surface of :meth:`drawn`
        (vertices moved by the particles, long edges split, slivers flipped and relaxed), vertex velocities,
        topology version, faces and the per-face ``fragment`` and ``crack``."""
        d = self.drawn(positions)
        if self._view_faces is None or self._view_of != self.version or not np.array_equal(d.faces, self._view_faces):
            self._view_faces, self._view_of = d.faces, self.version
            self._view_version += 1
        vel = None
        if velocities is not None:
            vel = self.vertex_velocities(positions, velocities)
            if d.added is not None:
                vel = np.concatenate([vel, self.vertex_velocities(positions, velocities, at=d.added)])
        return MeshView(
            name=f"{self.body_name}_surface",
            points=d.points,
            velocities=vel,
            topology_version=self._view_version,
            faces=d.faces,
            face_attributes={"fragment": self.face_fragment[d.face_parent], "crack": self.face_crack[d.face_parent]},
        )

    def drawn(self, positions) -> DrawnSurface:
        """The surface to draw at particle ``positions`` [m] [particle_count, 3] (step 9 of the method,
        :func:`drawn_surface`): the vertices of :meth:`vertex_positions`; edges drawn longer than 3 spacings split at
        their rest-space midpoints, which are embedded in the particles like every vertex; slivers made by the motion
        flipped away and relaxed (their vertices move towards their neighbours). Depends on the positions only, not
        on earlier frames."""
        return drawn_surface(
            self.vertex_positions(positions),
            self.faces,
            self.rest_vertices,
            self.vertex_fragment,
            self._face_shell,
            self._face_patch,
            self.face_crack,
            self.spacing,
            self._embedding.shape_functions,
            lambda at: self.vertex_positions(positions, at=at),
        )


def surface_states(surfaces) -> dict:
    """The checkpoint states (:meth:`FragmentSurfaces.checkpoint`) of a list of surfaces, by index as a string; {}
    for None."""
    return {} if surfaces is None else {str(i): f.checkpoint() for i, f in enumerate(surfaces)}


def with_states(surfaces, states) -> None:
    """Puts the states of :func:`surface_states` (or None: nothing) back into a list of surfaces made anew."""
    for i, f in enumerate(surfaces if states else ()):
        f.restore(states.get(str(i), {}))
