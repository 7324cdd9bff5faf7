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
def law_coefficients(law, sigma, prm, tol):
    """Gradient coefficients (spectral.pair_coefficients) of the singular-value law ``law``."""
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


# ---------------------------------------------------------------- elastic stress laws


@ti.func
def linear_stress(F, prm):
    """Small strain: P = 2 mu eps + lam tr(eps) I, eps = sym(F) - I; tau = P F^T."""
    mu, lam = lame(prm)
    strain = 0.5 * (F + F.transpose()) - identity()
    piola = 2.0 * mu * strain + lam * (strain[0, 0] + strain[1, 1] + strain[2, 2]) * identity()
    return matmul_t(piola, F)


@ti.func
def neo_hookean_stress(F, prm):
    """tau = mu (F F^T - I) + lam log(J) I."""
    mu, lam = lame(prm)
    J = ti.max(det(F), J_FLOOR)
    return mu * (matmul_t(F, F) - identity()) + lam * ti.log(J) * identity()


@ti.func
def corotated_stress(F, U, V, coeff, prm):
    """tau = 2 mu (F - R) F^T + lam (J - 1) J I, R the polar rotation."""
    mu, lam = lame(prm)
    R = isotropic_uv(F, U, V, coeff, unit_sigma, prm)
    J = det(F)
    return 2.0 * mu * matmul_t(F - R, F) + lam * (J - 1.0) * J * identity()


@ti.func
def stvk_hencky_stress(F, U, V, coeff, prm):
    """tau = U (2 mu log S + lam tr(log S)) U^T, computed as P F^T."""
    return matmul_t(isotropic_uv(F, U, V, coeff, hencky_piola_sigma, prm), F)


@ti.func
def fluid_deformation(F):
    """J^(1/3) I: a weakly compressible fluid forgets all but its volume change."""
    return ti.pow(ti.max(det(F), J_FLOOR), 1.0 / 3.0) * identity()


# ---------------------------------------------- per-law kernels (differentiated by Taichi)


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
        F_corrected[slot, p] += params[W_FLUID] * fluid_deformation(F[slot, p])


def _plain_stress_kernel(law):
    @ti.kernel
    def kernel(
        F: ti.types.ndarray(),
        slot: ti.i32,
        params: ti.types.ndarray(),
        stress: ti.types.ndarray(),
        serial: ti.template(),
    ):
        ti.loop_config(serialize=serial)
        for p in range(F.shape[1]):
            stress[slot, p] = law(F[slot, p], material_constants(params))

    return kernel


def _spectral_stress_kernel(law):
    @ti.kernel
    def kernel(
        F: ti.types.ndarray(),
        slot: ti.i32,
        U: ti.types.ndarray(),
        V: ti.types.ndarray(),
        coeff: ti.types.ndarray(),
        params: ti.types.ndarray(),
        stress: ti.types.ndarray(),
        serial: ti.template(),
    ):
        ti.loop_config(serialize=serial)
        for p in range(F.shape[1]):
            prm = material_constants(params)
            stress[slot, p] = law(F[slot, p], U[slot, p], V[slot, p], coeff[slot, p], prm)

    return kernel


stress_linear = _plain_stress_kernel(linear_stress)
stress_neo_hookean = _plain_stress_kernel(neo_hookean_stress)
stress_corotated = _spectral_stress_kernel(corotated_stress)
stress_stvk_hencky = _spectral_stress_kernel(stvk_hencky_stress)


# --------------------------------------------------- forward: all laws, chosen at run time

LINEAR, COROTATED, NEO_HOOKEAN, STVK_HENCKY = 0, 1, 2, 3


@ti.func
def constitutive_update(F: ti.template(), F_corrected: ti.template(), stress: ti.template(),
                        records: ti.template(), material: ti.template(), slot, p):  # fmt: skip
    """Plastic mixture then elastic law for particle p, recording what the backward needs.

    Writes F_corrected and stress, and into ``records`` (an
    :data:`~taichi_mpm.kernels.arguments.Records`) the SVD factors and gradient coefficients
    that the per-law kernels above read in reverse mode. ``material`` is the material's pack
    (:func:`~taichi_mpm.kernels.arguments.material`). With ``material.share_basis`` (a single
    SVD-based plastic law, or none, before an SVD-based elastic law) F_corrected =
    U diag(S') V^T and the elastic law reuses the trial SVD.
    """
    elastic_kind = material.elastic_kind
    share_basis = material.share_basis
    tol = material.spectral_tol
    prm = material_constants(material.params)
    Ft = F[slot, p]
    w_von_mises, w_sand = material.params[W_VON_MISES], material.params[W_SAND]
    spectral_elastic = (elastic_kind == COROTATED) | (elastic_kind == STVK_HENCKY)
    elastic_law = LAW_HENCKY
    if elastic_kind == COROTATED:
        elastic_law = LAW_UNIT
    Fc = ti.Matrix.zero(float, 3, 3)
    if w_von_mises != 0 or w_sand != 0 or share_basis != 0:
        u, s, v = singular_values(Ft)
        records.trial_U[slot, p] = u
        records.trial_V[slot, p] = v
        s_next = s
        if w_von_mises != 0:
            c = law_coefficients(LAW_VON_MISES, s, prm, tol)
            records.coeff_von_mises[slot, p] = c
            Fc += w_von_mises * isotropic_uv(Ft, u, v, c, von_mises_sigma, prm)
            s_next = von_mises_sigma(s, prm)
        if w_sand != 0:
            c = law_coefficients(LAW_SAND, s, prm, tol)
            records.coeff_sand[slot, p] = c
            Fc += w_sand * isotropic_uv(Ft, u, v, c, drucker_prager_sigma, prm)
            s_next = drucker_prager_sigma(s, prm)
        if share_basis != 0:
            records.coeff_elastic[slot, p] = law_coefficients(elastic_law, s_next, prm, tol)
    if material.params[W_IDENTITY] != 0:
        Fc += material.params[W_IDENTITY] * Ft
    if material.params[W_FLUID] != 0:
        Fc += material.params[W_FLUID] * fluid_deformation(Ft)
    F_corrected[slot, p] = Fc
    if spectral_elastic and share_basis == 0:
        u, s, v = singular_values(Fc)
        records.elastic_U[slot, p] = u
        records.elastic_V[slot, p] = v
        records.coeff_elastic[slot, p] = law_coefficients(elastic_law, s, prm, tol)
    tau = ti.Matrix.zero(float, 3, 3)
    if elastic_kind == LINEAR:
        tau = linear_stress(Fc, prm)
    elif elastic_kind == NEO_HOOKEAN:
        tau = neo_hookean_stress(Fc, prm)
    else:
        U = records.elastic_U[slot, p]
        V = records.elastic_V[slot, p]
        if share_basis != 0:
            U = records.trial_U[slot, p]
            V = records.trial_V[slot, p]
        coeff = records.coeff_elastic[slot, p]
        if elastic_kind == COROTATED:
            tau = corotated_stress(Fc, U, V, coeff, prm)
        else:
            tau = stvk_hencky_stress(Fc, U, V, coeff, prm)
    stress[slot, p] = tau
