"""Build a scene: assemble only the effects it lists into a SecondOrderSystem."""

from __future__ import annotations

import ast
import contextlib
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from femrom import fem
from femrom._progress import Stage
from femrom.fem import Condensation
from femrom.mesh import MeshError, build_mesh
from femrom.scene._config import Scene
from femrom.scene._effects import Assembly, registered_effects
from femrom.scene._errors import SceneError
from femrom.scene._materials import element_materials
from femrom.scene._system import SecondOrderSystem
from femrom.solvers import make_solver


@dataclass(frozen=True, eq=False)
class FullOrderModel:
    """A built scene: the system, its space (for fields and rendering) and (q0, v0)."""

    scene: Scene
    system: SecondOrderSystem
    space: object
    initial_displacement: np.ndarray
    initial_velocity: np.ndarray
    timings: dict = field(default_factory=dict)

    @property
    def times(self) -> np.ndarray:
        return self.scene.time.dt * np.arange(self.scene.time.n_steps + 1)

    def free_coordinates(self, component: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Where the free dofs of one field component sit (the space's first component by default:
        a line's values ``w`` or ``u``, not its slopes; a solid's ``x``).

        Returns
        -------
        index : (k,) int ndarray
            Positions of the component's free dofs in a free-dof vector (``q``, a column of
            a snapshot matrix), in the space's node order.
        points : (dim, k) ndarray
            Their coordinates (mesh nodes; on P2 solids also edge midpoints).
        """
        dofs, points = self.space.coordinates(component)
        free = self.system.condensation.free
        index = np.minimum(np.searchsorted(free, dofs), free.size - 1)
        keep = free[index] == dofs                    # the fixed dofs have no position
        return index[keep], np.asarray(points)[:, keep]


def _assemble(scene: Scene, mesh, timings: dict):
    """The system of the listed effects on ``mesh``; fills ``timings`` per stage."""
    with _timed(timings, "space"):
        space = make_space(scene, mesh)
        with _located("boundary"):
            condensation = _condensation(scene, space)
        material = _material(scene, space)
    build = Assembly(scene=scene, space=space, condensation=condensation, timings=timings, material=material)
    known = registered_effects()
    for name in sorted(scene.effect_names, key=lambda name: list(known).index(name)):
        effect = known[name]()
        effect.assemble(build, dict(scene.effect(name).options))

    output_matrix = None
    output_names = ()
    if scene.outputs.probes:
        with _timed(timings, "outputs"):
            rows = []
            for i, p in enumerate(scene.outputs.probes):
                kind = "averages" if p.average else "probes"
                with _located(f"outputs.{kind}[{i}] ({p.name})"):
                    rows.append(condensation.columns(space.output_row(p)))
            output_matrix = sp.vstack(rows).tocsr()
            output_names = tuple(p.name for p in scene.outputs.probes)

    system = SecondOrderSystem(
        mass=build.mass, stiffness=build.stiffness, damping=build.damping,
        input_matrix=build.input_matrix, inputs=build.inputs,
        output_matrix=output_matrix, nonlinear=build.nonlinear_forces or None, load=build.load,
        condensation=condensation, output_names=output_names,
        metadata={"scene": scene.name, "effects": scene.effect_names, "n_total": space.n_total,
                  "n_free": condensation.n_free, "element": scene.structure.element},
    )
    with _timed(timings, "initial_conditions"):
        q0, v0 = _initial_state(scene, space, system)
    return system, space, q0, v0


@contextlib.contextmanager
def _timed(timings: dict, name: str):
    tic = time.perf_counter()
    yield
    timings[name] = time.perf_counter() - tic


def _material(scene: Scene, space):
    """What the effects read as the material: ``[material]``, or ``[materials]`` per element."""
    if scene.material is not None:
        return scene.material
    if not isinstance(space, fem.SolidSpace):
        raise SceneError("[materials] (a material per region) needs a solid mesh; a line takes [material]")
    return element_materials(scene.materials, space.mesh)


def make_space(scene: Scene, mesh):
    element = scene.structure.element
    dim = mesh.p.shape[0]
    if dim == 1:
        if element == "p2":
            raise SceneError("element 'p2' is for solids; a line takes 'hermite' or 'p1'")
        return fem.LineSpace(mesh, element)
    if dim == 3:
        if element == "hermite":
            raise SceneError("element 'hermite' is for beams on a line; a solid takes 'p1' or 'p2'")
        return fem.SolidSpace(mesh, element)
    raise SceneError(f"no structure model for {dim}D meshes yet (1D lines and 3D solids)")


def build(scene: Scene, *, mesh=None) -> FullOrderModel:
    """Assemble the scene's effects, and nothing else, on the free dofs.

    Parameters
    ----------
    scene : Scene
    mesh : skfem.Mesh, optional
        Use this mesh instead of generating the scene's geometry (tests, imported meshes).
    """
    timings = {}
    names = scene.effect_names
    known = registered_effects()
    for provides, what in (("mass", "a dynamic scene needs"), ("stiffness", "list")):
        listed = [n for n in names if known[n].provides == provides]
        valid = [n for n, e in known.items() if e.provides == provides]
        if provides == "mass" and not listed:
            raise SceneError(f"{what} the {' or '.join(repr(v) for v in valid)} effect")
        if provides == "mass" and len(listed) != 1:
            raise SceneError(f"list exactly one mass effect of {', '.join(valid)}; got {listed}")
        if provides == "stiffness" and not listed:
            raise SceneError(f"list at least one stiffness effect of {', '.join(valid)}; got none")

    with _timed(timings, "mesh"):
        if mesh is None:
            mesh = build_mesh(scene.structure.geometry, dict(scene.structure.parameters))
    # assembly takes seconds to tens of seconds at 1e5-1e6 dofs: one line on a terminal
    with Stage(f"{scene.name}: assembling {', '.join(names)}"):
        system, space, q0, v0 = _assemble(scene, mesh, timings)
    return FullOrderModel(scene, system, space, q0, v0, timings)


def _condensation(scene, space) -> Condensation:
    fixed = [space.boundary_dofs(name, clamped=True) for name in scene.boundary.clamped]
    fixed += [space.boundary_dofs(name, clamped=False) for name in scene.boundary.pinned]
    fixed = np.concatenate(fixed) if fixed else np.zeros(0, dtype=np.int64)
    return Condensation.from_fixed(space.n_total, fixed)


@contextlib.contextmanager
def _located(where: str):
    """A space's or mesh's complaint about one scene entry, as a SceneError naming the entry."""
    try:
        yield
    except (fem.SpaceError, MeshError) as exc:
        raise SceneError(f"[{where}] {exc}") from None


def _initial_state(scene, space, system):
    ic = scene.initial_conditions
    n = system.n_dofs
    cond = system.condensation
    if ic.kind == "zero":
        return np.zeros(n), np.zeros(n)
    if ic.kind == "static_load":
        with _located("initial_conditions.load"):
            f = cond.vector(space.load_vector(ic.load))
        if not cond.fixed.size:
            raise SceneError("[initial_conditions] static_load needs supports: the model has no [boundary] "
                             "conditions, so its stiffness is singular (rigid-body motion); use kind = 'zero' "
                             "or 'expression' for a free structure")
        solver = make_solver(system.stiffness, strategy=scene.time.solver,
                             near_nullspace=_near_nullspace(space, cond))
        q = solver.solve(f)
        return _checked_static(system.stiffness, f, q), np.zeros(n)
    if ic.kind == "mode":
        shape = _mode_shape(system, ic.index)
        dofs, _ = space.coordinates(ic.component)
        free_component = np.isin(cond.free, dofs)
        peak = np.max(np.abs(shape[free_component])) if free_component.any() else np.max(np.abs(shape))
        return ic.amplitude * shape / peak, np.zeros(n)
    if ic.kind == "expression":
        q = cond.vector(space.interpolate(_expression(ic.displacement), ic.component))
        v = cond.vector(space.interpolate(_expression(ic.velocity), ic.component))
        return q, v
    raise SceneError(f"unknown initial condition {ic.kind!r}")


#: ``||K||_1 ||q|| / ||f||`` (a lower bound of cond(K)) above which a static solution is refused:
#: at 1 / (1e4 eps) the solve has lost all but ~4 digits (a mechanism, a support that holds nothing).
STATIC_CONDITION_LIMIT = 1.0 / (1e4 * np.finfo(float).eps)


def _checked_static(K, f, q) -> np.ndarray:
    """``q`` of ``K q = f``, or one SceneError when ``K`` is (near) singular or the solve is not finite."""
    norm_f = float(np.linalg.norm(f))
    if not np.all(np.isfinite(q)):
        raise SceneError("[initial_conditions] static_load: the static solution is not finite (singular stiffness: "
                         "a mechanism or missing supports)")
    if norm_f == 0:
        return q
    estimate = float(abs(K).sum(axis=0).max()) * float(np.linalg.norm(q)) / norm_f
    if estimate > STATIC_CONDITION_LIMIT:
        raise SceneError(f"[initial_conditions] static_load: the stiffness is (near) singular, condition >= "
                         f"{estimate:.1e} (a mechanism or supports that do not hold the structure); "
                         "check [boundary]")
    return q


def _near_nullspace(space, cond):
    modes = getattr(space, "rigid_body_modes", None)
    return None if modes is None else cond.vector(modes())


def _mode_shape(system, index):
    """Eigenvector ``index`` (1-based) of ``K phi = omega^2 M phi`` by shift-invert Lanczos."""
    from scipy.sparse.linalg import eigsh

    if index > system.n_dofs - 1:
        raise SceneError(f"[initial_conditions] mode index {index} exceeds the {system.n_dofs - 1} modes "
                         f"computable on this model ({system.n_dofs} free dofs)")
    k = min(index + 2, system.n_dofs - 1)
    values, vectors = eigsh(system.stiffness.tocsc(), k=k, M=system.mass.tocsc(), sigma=0.0, which="LM")
    order = np.argsort(values)
    return vectors[:, order[index - 1]]


_EXPRESSION_NAMES = {name: getattr(np, name) for name in
                     ("sin", "cos", "tan", "exp", "log", "sqrt", "sinh", "cosh", "tanh", "arctan",
                      "abs", "where", "pi")}


#: The syntax an initial-condition expression may use: arithmetic, comparisons and calls of
#: :data:`_EXPRESSION_NAMES` on numbers and ``x, y, z`` (no attributes, subscripts, strings or
#: collections: nothing that can build a huge object or reach outside numpy).
_EXPRESSION_NODES = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.BoolOp, ast.Compare, ast.IfExp, ast.Call,
                     ast.Name, ast.Load, ast.Constant, ast.operator, ast.unaryop, ast.boolop, ast.cmpop)


class _FloatLiterals(ast.NodeTransformer):
    """Integer literals as floats, so that ``9 ** 9 ** 9`` overflows to inf at once instead of
    computing an integer of 370 million digits."""

    def visit_Constant(self, node):
        if isinstance(node.value, int) and not isinstance(node.value, bool):
            return ast.copy_location(ast.Constant(float(node.value)), node)
        return node


def _expression(text: str):
    """A numpy expression of ``x, y, z`` built from :data:`_EXPRESSION_NAMES` and numbers."""
    if not isinstance(text, str):
        raise SceneError(f"[initial_conditions] an expression must be a string, got {text!r}")
    try:
        tree = ast.parse(text, "<initial condition>", mode="eval")
    except SyntaxError as exc:
        raise SceneError(f"[initial_conditions] cannot parse expression {text!r}: {exc.msg}") from None
    allowed = set(_EXPRESSION_NAMES) | {"x", "y", "z"}
    for node in ast.walk(tree):
        if not isinstance(node, _EXPRESSION_NODES) or (
                isinstance(node, ast.Constant) and not isinstance(node.value, (int, float))) or (
                isinstance(node, ast.Call) and (node.keywords or not isinstance(node.func, ast.Name))):
            what = repr(node.value) if isinstance(node, ast.Constant) else type(node).__name__.lower()
            raise SceneError(f"[initial_conditions] {what} is not allowed in {text!r}; an expression uses "
                             "numbers, x, y, z, arithmetic, comparisons and the functions "
                             f"{', '.join(n for n in _EXPRESSION_NAMES if n != 'pi')}")
        if isinstance(node, ast.Name) and node.id not in allowed:
            raise SceneError(f"[initial_conditions] unknown name {node.id!r} in {text!r}; "
                             f"valid: x, y, z, {', '.join(_EXPRESSION_NAMES)}")
    code = compile(ast.fix_missing_locations(_FloatLiterals().visit(tree)), "<initial condition>", "eval")

    def evaluate(x, y, z):
        with np.errstate(all="ignore"):
            try:
                value = eval(code, {"__builtins__": {}}, {**_EXPRESSION_NAMES, "x": x, "y": y, "z": z})
            except OverflowError:
                raise SceneError(f"[initial_conditions] expression {text!r} overflows (a value beyond "
                                 "1.8e308)") from None
            except (ArithmeticError, TypeError, ValueError) as exc:
                raise SceneError(f"[initial_conditions] expression {text!r} cannot be evaluated: {exc}") from None
        try:
            value = np.broadcast_to(np.asarray(value, dtype=float), np.shape(x)).copy()
        except (TypeError, ValueError):
            raise SceneError(f"[initial_conditions] expression {text!r} does not give one number per "
                             "node") from None
        bad = ~np.isfinite(value)
        if bad.any():
            raise SceneError(f"[initial_conditions] expression {text!r} is not finite at {int(bad.sum())} of "
                             f"{value.size} nodes (first at x={np.ravel(x)[np.argmax(np.ravel(bad))]:.6g})")
        return value

    return evaluate

