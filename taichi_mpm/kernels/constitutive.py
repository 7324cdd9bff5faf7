"""Built-in constitutive laws as Taichi functions, one small kernel per law.

A plastic mixture is applied as one kernel per law, each adding its weighted share to
F_corrected; the elastic law is one kernel per kind. Only the kernels a material uses
are ever compiled, and no kernel branches on the law, which keeps Taichi's reverse-mode
compile short. Parameter layout: taichi_mpm.materials.PARAMETER_NAMES.
"""

import math

import taichi as ti

from taichi_mpm.kernels.linalg import det, identity, matmul_t
from taichi_mpm.kernels.spectral import isotropic_uv, pair_coefficients, singular_values

# Indices into the parameter array (kept in sync with materials.PARAMETER_NAMES).
E, NU, YIELD_STRESS, FRICTION_ANGLE, COHESION = 0, 1, 2, 3, 4
W_IDENTITY, W_VON_MISES, W_SAND, W_FLUID = 5, 6, 7, 8

SIGMA_FLOOR = 1e-2  # smallest singular value entering a logarithm
SAND_SIGMA_FLOOR = 0.05  # Klar et al. clamp for sand
NORM_TINY = 1e-30  # keeps sqrt differentiable at zero
J_FLOOR = 1e-6


@ti.func
def material_constants(params: ti.template()):
    """E, nu, yield stress, friction angle (deg), cohesion."""
    return ti.Vector(
        [params[E], params[NU], params[YIELD_STRESS], params[FRICTION_ANGLE], params[COHESION]]
    )


@ti.func
def lame(prm):
    """Shear modulus and first Lame parameter from E and nu."""
    return prm[E] / (2.0 * (1.0 + prm[NU])), prm[E] * prm[NU] / (
        (1.0 + prm[NU]) * (1.0 - 2.0 * prm[NU])
    )


@ti.func
def total(a):
    return a[0] + a[1] + a[2]


@ti.func
def deviatoric(eps):
    """Deviatoric part of a principal strain and its norm."""
    eps_hat = eps - total(eps) / 3.0
    return eps_hat, ti.sqrt(total(eps_hat * eps_hat) + NORM_TINY)


# ------------------------------------------------------ laws on singular values (vec3 -> vec3)


@ti.func
def unit_sigma(sigma, prm):
    """Rotation of the polar decomposition: every singular value mapped to 1."""
    return ti.Vector([1.0, 1.0, 1.0]) + 0.0 * sigma


@ti.func
def von_mises_sigma(sigma, prm):
    """Singular values after the von Mises return mapping on the Hencky strain."""
    mu, _ = lame(prm)
    eps = ti.log(ti.max(ti.abs(sigma), SIGMA_FLOOR))
    eps_hat, norm = deviatoric(eps)
    excess = ti.max(norm - prm[YIELD_STRESS] / (2.0 * mu), 0.0)
    return ti.exp(eps - excess / norm * eps_hat)


@ti.func
def drucker_prager_sigma(sigma, prm):
    """Singular values after the Drucker-Prager sand return mapping (Klar et al. 2016)."""
    mu, lam = lame(prm)
    eps = ti.log(ti.max(ti.abs(sigma), SAND_SIGMA_FLOOR))
    eps_hat, norm = deviatoric(eps)
    trace = total(eps)
    sin_phi = ti.sin(prm[FRICTION_ANGLE] * (math.pi / 180.0))
    alpha = ti.sqrt(2.0 / 3.0) * 2.0 * sin_phi / (3.0 - sin_phi)
    cohesion = prm[COHESION]
    excess = norm + (3.0 * lam + 2.0 * mu) / (2.0 * mu) * (trace - cohesion) * alpha
    sheared = eps - ti.max(excess, 0.0) / norm * eps_hat
    at_apex = ti.cast(trace >= cohesion, float)
    return ti.exp(at_apex * cohesion / 3.0 + (1.0 - at_apex) * sheared)


@ti.func
def hencky_piola_sigma(sigma, prm):
    """First Piola-Kirchhoff singular values of StVK on the Hencky strain."""
    mu, lam = lame(prm)
    eps = ti.log(ti.max(ti.abs(sigma), SIGMA_FLOOR))
    tau = 2.0 * mu * eps + lam * total(eps)
    safe = ti.select(sigma >= 0, ti.max(sigma, J_FLOOR), ti.min(sigma, -J_FLOOR))
    return tau / safe


# ------------------------------------------------------------- SVD and its coefficients

NO_LAW, LAW_UNIT, LAW_VON_MISES, LAW_SAND, LAW_HENCKY = -1, 0, 1, 2, 3


@ti.func
def law_sigma(law, sigma, prm):
    """The singular-value law ``law`` applied to sigma (forward only)."""
    out = sigma
    if law == LAW_UNIT:
        out = unit_sigma(sigma, prm)
    elif law == LAW_VON_MISES:
        out = von_mises_sigma(sigma, prm)
    elif law == LAW_SAND:
        out = drucker_prager_sigma(sigma, prm)
    elif law == LAW_HENCKY:
        out = hencky_piola_sigma(sigma, prm)
    return out


@ti.func
def law_coefficients(law, sigma, prm, tol):
    out = ti.Matrix.zero(float, 3, 2)
    if law == LAW_UNIT:
        out = pair_coefficients(sigma, unit_sigma, prm, tol)
    elif law == LAW_VON_MISES:
        out = pair_coefficients(sigma, von_mises_sigma, prm, tol)
    elif law == LAW_SAND:
        out = pair_coefficients(sigma, drucker_prager_sigma, prm, tol)
    elif law == LAW_HENCKY:
        out = pair_coefficients(sigma, hencky_piola_sigma, prm, tol)
    return out


@ti.kernel
def decompose(
    F: ti.types.ndarray(),
    slot: ti.i32,
    params: ti.types.ndarray(),
    law: ti.i32,
    coeff: ti.types.ndarray(),
    next_law: ti.i32,
    next_coeff: ti.types.ndarray(),
    U: ti.types.ndarray(),
    V: ti.types.ndarray(),
    tol: float,
    serial: ti.template(),
):
    """SVD of F[slot] and the gradient coefficients of ``law`` (forward only).

    When ``next_law`` is set, also the coefficients of ``next_law`` at the singular values
    ``law`` produces: U diag(law(S)) V^T is the SVD of the plastic law's output, so the
    elastic law that follows it shares this decomposition.
    """
    ti.loop_config(serialize=serial)
    for p in range(F.shape[1]):
        prm = material_constants(params)
        u, s, v = singular_values(F[slot, p])
        U[slot, p] = u
        V[slot, p] = v
        if law != NO_LAW:
            coeff[slot, p] = law_coefficients(law, s, prm, tol)
        if next_law != NO_LAW:
            s_next = s
            if law != NO_LAW:
                s_next = law_sigma(law, s, prm)
            next_coeff[slot, p] = law_coefficients(next_law, s_next, prm, tol)


# ------------------------------------------------------------------- plastic kernels


def _spectral_plastic_kernel(law, weight_index: int):
    @ti.kernel
    def kernel(
        F: ti.types.ndarray(),
        slot: ti.i32,
        U: ti.types.ndarray(),
        V: ti.types.ndarray(),
        coeff: ti.types.ndarray(),
        params: ti.types.ndarray(),
        F_corrected: ti.types.ndarray(),
        serial: ti.template(),
    ):
        ti.loop_config(serialize=serial)
        for p in range(F.shape[1]):
            prm = material_constants(params)
            G = isotropic_uv(F[slot, p], U[slot, p], V[slot, p], coeff[slot, p], law, prm)
            F_corrected[slot, p] += params[weight_index] * G

    return kernel


plastic_von_mises = _spectral_plastic_kernel(von_mises_sigma, W_VON_MISES)
plastic_von_mises.__doc__ = "F_corrected[slot] += w * von Mises return mapping of F[slot]."
plastic_sand = _spectral_plastic_kernel(drucker_prager_sigma, W_SAND)
plastic_sand.__doc__ = "F_corrected[slot] += w * Drucker-Prager return mapping of F[slot]."


@ti.kernel
def plastic_identity(
    F: ti.types.ndarray(),
    slot: ti.i32,
    params: ti.types.ndarray(),
    F_corrected: ti.types.ndarray(),
    serial: ti.template(),
):
    """F_corrected[slot] += w * F[slot]."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[1]):
        F_corrected[slot, p] += params[W_IDENTITY] * F[slot, p]


@ti.kernel
def plastic_fluid(
    F: ti.types.ndarray(),
    slot: ti.i32,
    params: ti.types.ndarray(),
    F_corrected: ti.types.ndarray(),
    serial: ti.template(),
):
    """F_corrected[slot] += w * J^(1/3) I (weakly compressible fluid)."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[1]):
        J = ti.max(det(F[slot, p]), J_FLOOR)
        F_corrected[slot, p] += params[W_FLUID] * ti.pow(J, 1.0 / 3.0) * identity()


# ------------------------------------------------------------------- elastic kernels


@ti.kernel
def stress_linear(
    F: ti.types.ndarray(),
    slot: ti.i32,
    params: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    serial: ti.template(),
):
    """Small strain: P = 2 mu eps + lam tr(eps) I, eps = sym(F) - I; tau = P F^T."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[1]):
        mu, lam = lame(material_constants(params))
        Fp = F[slot, p]
        strain = 0.5 * (Fp + Fp.transpose()) - identity()
        piola = 2.0 * mu * strain + lam * (strain[0, 0] + strain[1, 1] + strain[2, 2]) * identity()
        stress[slot, p] = matmul_t(piola, Fp)


@ti.kernel
def stress_neo_hookean(
    F: ti.types.ndarray(),
    slot: ti.i32,
    params: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    serial: ti.template(),
):
    """tau = mu (F F^T - I) + lam log(J) I."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[1]):
        mu, lam = lame(material_constants(params))
        Fp = F[slot, p]
        J = ti.max(det(Fp), J_FLOOR)
        stress[slot, p] = mu * (matmul_t(Fp, Fp) - identity()) + lam * ti.log(J) * identity()


@ti.kernel
def stress_corotated(
    F: ti.types.ndarray(),
    slot: ti.i32,
    U: ti.types.ndarray(),
    V: ti.types.ndarray(),
    coeff: ti.types.ndarray(),
    params: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    serial: ti.template(),
):
    """tau = 2 mu (F - R) F^T + lam (J - 1) J I."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[1]):
        prm = material_constants(params)
        mu, lam = lame(prm)
        Fp = F[slot, p]
        R = isotropic_uv(Fp, U[slot, p], V[slot, p], coeff[slot, p], unit_sigma, prm)
        J = det(Fp)
        stress[slot, p] = 2.0 * mu * matmul_t(Fp - R, Fp) + lam * (J - 1.0) * J * identity()


@ti.kernel
def stress_stvk_hencky(
    F: ti.types.ndarray(),
    slot: ti.i32,
    U: ti.types.ndarray(),
    V: ti.types.ndarray(),
    coeff: ti.types.ndarray(),
    params: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    serial: ti.template(),
):
    """tau = U (2 mu log S + lam tr(log S)) U^T, computed as P F^T."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[1]):
        prm = material_constants(params)
        Fp = F[slot, p]
        piola = isotropic_uv(Fp, U[slot, p], V[slot, p], coeff[slot, p], hencky_piola_sigma, prm)
        stress[slot, p] = matmul_t(piola, Fp)
