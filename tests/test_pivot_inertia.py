"""Bodies that can exist: the parallel-axis helpers, their refusals, and every built-in scene checked.

A top's inertia is given about its pivot; with its mass and centre-of-mass offset that fixes the
central inertia, which must be positive definite and meet the triangle inequality (issue 75: the old
``heavy_top``, ``(1, 2, 3)`` about the pivot with 1 kg at ``(0.1, 0.05, 0.3)`` m, implied central
moments ``(0.907, 1.900, 2.988)``).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrot
from jaxrot import torques
from jaxrot.scenes import FLUID_SCENES, SCENES, THERMAL_SCENES


BUILDERS = {**SCENES, **FLUID_SCENES, **THERMAL_SCENES}
OFFSET = np.array([0.1, 0.05, 0.3])
G = 9.81  # the built-in scenes are in SI units; their weights are m g with g = 9.81 m/s²


def _central_moments(scene):
    """Independent of jaxrot's helpers: the principal moments about each body's centre of mass."""
    inertia = np.asarray(scene.inertia, np.float64)
    tensors = inertia if inertia.shape[-2:] == (3, 3) else inertia[..., :, None] * np.eye(3)
    for term in getattr(scene.torque, "terms", (scene.torque,)):
        if isinstance(term, torques.Gravity):
            p = scene.args[term.key]
            assert scene.mass is not None, f"{scene.name}: a weight on an offset centre of mass needs `mass`"
            np.testing.assert_allclose(np.linalg.norm(np.asarray(p["weight"])), G * scene.mass, rtol=1e-12)
            r = np.asarray(p["offset_body"], np.float64)
            tensors = tensors - scene.mass * (r @ r * np.eye(3) - np.outer(r, r))
    return np.linalg.eigvalsh(tensors)


@pytest.mark.parametrize("name", sorted(BUILDERS))
def test_every_built_in_scene_is_a_body_that_can_exist(name):
    scene = BUILDERS[name]()
    if scene.inertia is None:  # overdamped: no inertia to exist or not
        assert scene.fluid is not None
        return
    moments = _central_moments(scene)
    assert np.all(moments > 0), f"{name}: central moments {moments} are not all positive"
    slack = moments.sum(-1) - 2 * moments.max(-1)  # I1 + I2 - I3 with I3 the largest: >= 0 for a real body
    assert np.all(slack >= -1e-12 * moments.max(-1)), f"{name}: central moments {moments} break I1 + I2 >= I3"
    central = scene.central_inertia()  # jaxrot's own check agrees
    if scene.mass is not None:
        np.testing.assert_allclose(np.linalg.eigvalsh(np.asarray(central)), moments, rtol=1e-12)


def test_heavy_top_central_inertia_is_the_documented_one():
    central = np.asarray(SCENES["heavy_top"]().central_inertia())
    np.testing.assert_allclose(np.linalg.eigvalsh(central), [1.157, 1.900, 2.988], atol=5e-4)


def test_central_inertia_refuses_the_old_heavy_top_naming_the_fix():
    with pytest.raises(ValueError, match=r"(?s)`pivot`.*0\.907.*triangle.*jaxrot\.pivot_inertia"):
        jaxrot.central_inertia(jnp.array([1.0, 2.0, 3.0]), 1.0, jnp.asarray(OFFSET))


def test_central_inertia_refuses_a_central_inertia_that_is_not_positive():
    with pytest.raises(ValueError, match="not all positive"):
        jaxrot.central_inertia(jnp.array([0.05, 1.0, 1.0]), 1.0, jnp.array([0.0, 0.0, 0.3]))


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"mass": -1.0}, "`mass` must be a finite mass > 0"),
        ({"mass": float("nan")}, "`mass` must be a finite mass > 0"),
        ({"offset": jnp.array([0.0, 0.3])}, r"`offset` must be a finite body-frame vector \(3,\)"),
        ({"central": jnp.array([1.0, 2.0, 3.5])}, "`central` is not a physical body"),
    ],
)
def test_pivot_inertia_checks_its_arguments_before_computing(kwargs, match):
    given = {"central": jnp.array([1.0, 2.0, 2.5]), "mass": 1.0, "offset": jnp.asarray(OFFSET), **kwargs}
    with pytest.raises(ValueError, match=match):
        jaxrot.pivot_inertia(**given)


def test_pivot_and_central_inertia_are_inverse_and_the_parallel_axis_theorem():
    central = jnp.array([[1.0, 0.1, 0.0], [0.1, 2.0, 0.05], [0.0, 0.05, 2.5]])
    pivot = jaxrot.pivot_inertia(central, 2.0, jnp.asarray(OFFSET))
    # Point masses: a sum over points of m (|x|² 𝟙 − x xᵀ) about the pivot, x = r + d about the centre.
    points = np.array([[0.3, -0.2, 0.1], [-0.3, 0.2, -0.1]])  # centred pair, 1 kg each
    about = lambda xs: sum(np.dot(x, x) * np.eye(3) - np.outer(x, x) for x in xs)  # noqa: E731
    np.testing.assert_allclose(about(points + OFFSET) - about(points), 2.0 * (OFFSET @ OFFSET * np.eye(3)
                               - np.outer(OFFSET, OFFSET)), atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(
        np.asarray(pivot) - np.asarray(central), about(points + OFFSET) - about(points)
    )
    np.testing.assert_allclose(jaxrot.central_inertia(pivot, 2.0, jnp.asarray(OFFSET)), central, atol=1e-12)
    # Traced: no check, the same values.
    traced = jax.jit(jaxrot.central_inertia)(pivot, 2.0, jnp.asarray(OFFSET))
    np.testing.assert_allclose(traced, central, atol=1e-12)


def test_a_scene_with_a_weight_but_no_mass_is_refused():
    scene = SCENES["heavy_top"]()._replace(mass=None)
    with pytest.raises(ValueError, match="no `mass`"):
        scene.central_inertia()


def test_the_old_heavy_top_scene_is_refused():
    scene = SCENES["heavy_top"]()._replace(inertia=jnp.array([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match=r"`heavy_top\.inertia`.*not a body that can exist"):
        scene.central_inertia()


def test_mujoco_accepts_the_built_in_tops_and_refuses_the_old_heavy_top():
    """MuJoCo checks a body's central inertia (A + B >= C) when it compiles a model: the peer agrees."""
    mujoco = pytest.importorskip("mujoco")

    def compile_top(central, offset, mass):
        full = " ".join(f"{central[i, j]:.15g}" for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))
        xml = (
            '<mujoco><worldbody><body><joint type="ball"/>'
            f'<inertial pos="{offset[0]} {offset[1]} {offset[2]}" mass="{mass}" fullinertia="{full}"/>'
            "</body></worldbody></mujoco>"
        )
        return mujoco.MjModel.from_xml_string(xml)

    for name in ("heavy_top", "lagrange_top"):
        scene = SCENES[name]()
        offset = np.asarray(scene.args["gravity"]["offset_body"])
        compile_top(np.asarray(scene.central_inertia()), offset, scene.mass)
    # The old heavy_top, unchecked: (1, 2, 3) about the pivot less the parallel-axis term of 1 kg.
    old = np.diag([1.0, 2.0, 3.0]) - (OFFSET @ OFFSET * np.eye(3) - np.outer(OFFSET, OFFSET))
    with pytest.raises(ValueError, match=r"A \+ B >= C"):
        compile_top(old, OFFSET, 1.0)
