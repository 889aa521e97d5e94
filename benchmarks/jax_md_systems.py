"""jax_md's rigid-body test system, built once for the benchmark and the tests of `jaxrot.jax_md`.

The tetrahedra of jax_md's tests/rigid_body_test.py: `rigid_body.point_union_shape` of
`rigid_body.tetrahedron` stretched by (1, 2, 3) (principal moments `MOMENTS`, mass 4), soft-sphere
interactions (`energy.soft_sphere_pair`) in a periodic box at number density 0.1; and the same bodies
free (no interactions, free space: a thermostat alone). Used by benchmarks/jax_md_rigid.py,
benchmarks/jax_md_brownian.py and tests/test_jax_md*.py (which put benchmarks/ on their path, as
tests/test_fluid_layer.py does): one definition of the system that the results files and the tests
describe. It lives beside the benchmarks, not in the package: it is a measurement's scene, not an
API (jax_md ships the shape itself). Importing it imports jax_md (ImportError without it).
"""

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg


# jax_md computes at import, with JAX's default promotion rules (not jaxrot's strict test settings).
with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
    from jax_md import energy, quantity, rigid_body, space


MOMENTS = (5.4, 10.4, 13.4)  # the stretched tetrahedron's principal moments (point_union_shape's order)
DENSITY = 0.1


def shape():
    """The stretched tetrahedron (`rigid_body.RigidPointUnion`): ``shape().mass()`` is jax_md's mass."""
    return rigid_body.point_union_shape(
        rigid_body.tetrahedron.points * jnp.array([[1.0, 2.0, 3.0]]), rigid_body.tetrahedron.masses
    )


def bodies(n, box, key):
    """``n`` bodies at uniform centres in ``[0, box)³`` with uniform random orientations (float64)."""
    k_position, k_orientation = jax.random.split(key)
    center = box * jax.random.uniform(k_position, (n, 3), jnp.float64)
    q = jax.vmap(lambda k: rigid_body._random_quaternion(k, jnp.float64))(jax.random.split(k_orientation, n))
    return rigid_body.RigidBody(center, rigid_body.Quaternion(q))


def free_energy(position, **kwargs):
    """No interactions: each body's thermostat alone (zero, with the positions' dependence)."""
    return 0.0 * jnp.sum(position.center)


def free_system(n, key=1):
    """``(energy_fn, shift_fn, bodies)``: ``n`` free bodies in free space (box 100 for the centres)."""
    _, shift = space.free()
    return free_energy, shift, bodies(n, 100.0, jax.random.key(key))


def tetrahedra(n=40, density=DENSITY, key=0):
    """``(energy_fn, shift_fn, bodies)``: jax_md's soft-sphere tetrahedra in a periodic box."""
    box = quantity.box_size_at_number_density(n, density, 3)
    displacement, shift = space.periodic(box)
    energy_fn = rigid_body.point_energy(energy.soft_sphere_pair(displacement), shape())
    return energy_fn, shift, bodies(n, box, jax.random.key(key))


def favro(diffusion, t):
    """``(⟨P₁⟩, ⟨P₂⟩)``, ``(3,)`` each: the body axes' self-correlation after free rotational diffusion
    with diffusion ``(3,)`` about the body axes over ``t`` (Favro's closed form, as matrix exponentials of
    the generators ``E_k v = e_k × v``): the oracle of `jaxrot.jax_md.brownian`'s free bodies."""
    generators = [-np.cross(np.eye(3), e) for e in np.eye(3)]
    one = np.eye(3)
    g1 = sum(d * e @ e for d, e in zip(diffusion, generators, strict=True))
    g2 = sum(
        d * np.linalg.matrix_power(np.kron(e, one) + np.kron(one, e), 2)
        for d, e in zip(diffusion, generators, strict=True)
    )
    m1, m2 = scipy.linalg.expm(t * g1), scipy.linalg.expm(t * g2)
    return np.diag(m1), np.array([(3 * m2[4 * k, 4 * k] - 1) / 2 for k in range(3)])
