"""10-DOF vertical model of paper 000: spring assembly against the corrected hand-written Eqs. (1)-(10)."""

import numpy as np
import pytest

from railpaper import contact
from railpaper.data import DataError
from railpaper.experiments.partial_state_observer.records import suspension
from railpaper.models import vertical_10dof


@pytest.fixture(scope="module", params=["labels", "symbols"])
def vehicle(request):
    """Both readings of Table 1's suspension rows (paper 000; default 'labels')."""
    return vertical_10dof.load_parameters(**suspension(request.param))


@pytest.fixture(scope="module")
def model(vehicle):
    return vertical_10dof.build_model(vehicle)


def hand_written(v):
    """M, C, K typed from Eqs. (1)-(10) with the errata fixed (2K_s l_c² in (2); J_t β̈ and
    Z_w2 in (4); −K_p Z_t1 in (7)); k_H = wheelset contact stiffness."""
    Mc, Mt, Mw, Jc, Jt = (v.car_body_mass_kg, v.bogie_mass_kg, v.wheelset_mass_kg,
                          v.car_body_pitch_inertia_kg_m2, v.bogie_pitch_inertia_kg_m2)
    Kp, Cp, Ks, Cs = (v.primary_stiffness_N_per_m, v.primary_damping_Ns_per_m,
                      v.secondary_stiffness_N_per_m, v.secondary_damping_Ns_per_m)
    lc, lt = v.half_bogie_spacing_m, v.half_wheelbase_m
    kH = v.contact_stiffness_N_per_m

    def rows(k_s, k_p, k_h):
        # order: zc, bc, zt1, bt1, zt2, bt2, zw1, zw2, zw3, zw4
        return np.array([
            [2 * k_s, 0, -k_s, 0, -k_s, 0, 0, 0, 0, 0],                              # (1)
            [0, 2 * k_s * lc**2, k_s * lc, 0, -k_s * lc, 0, 0, 0, 0, 0],            # (2)
            [-k_s, k_s * lc, k_s + 2 * k_p, 0, 0, 0, -k_p, -k_p, 0, 0],             # (3)
            [0, 0, 0, 2 * k_p * lt**2, 0, 0, k_p * lt, -k_p * lt, 0, 0],            # (4)
            [-k_s, -k_s * lc, 0, 0, k_s + 2 * k_p, 0, 0, 0, -k_p, -k_p],            # (5)
            [0, 0, 0, 0, 0, 2 * k_p * lt**2, 0, 0, k_p * lt, -k_p * lt],            # (6)
            [0, 0, -k_p, k_p * lt, 0, 0, k_p + k_h, 0, 0, 0],                       # (7)
            [0, 0, -k_p, -k_p * lt, 0, 0, 0, k_p + k_h, 0, 0],                      # (8)
            [0, 0, 0, 0, -k_p, k_p * lt, 0, 0, k_p + k_h, 0],                       # (9)
            [0, 0, 0, 0, -k_p, -k_p * lt, 0, 0, 0, k_p + k_h],                      # (10)
        ], dtype=float)

    M = np.diag([Mc, Jc, Mt, Jt, Mt, Jt, Mw, Mw, Mw, Mw])
    return M, rows(Cs, Cp, 0.0), rows(Ks, Kp, kH)


def test_assembly_matches_corrected_equations(vehicle, model):
    M, C, K = hand_written(vehicle)
    np.testing.assert_allclose(model.M, M)
    np.testing.assert_allclose(model.C, C, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(model.K, K, rtol=1e-12, atol=1e-6)


def test_matrices_symmetric_and_definite(model):
    for X in (model.M, model.C, model.K):
        np.testing.assert_allclose(X, X.T)
    assert np.all(np.linalg.eigvalsh(model.K) > 0)       # the contact springs hold the vehicle
    assert np.all(np.linalg.eigvalsh(model.C) >= -1e-6 * np.abs(model.C).max())
    assert np.all(np.linalg.eigvals(model.A).real < 0)


def test_static_equilibrium(vehicle, model):
    """Under gravity the springs carry the weights the free-body diagrams say."""
    g = vehicle.gravity_m_per_s2
    d = vertical_10dof.static_deflection_m(model)
    Mc, Mt, Mw = vehicle.car_body_mass_kg, vehicle.bogie_mass_kg, vehicle.wheelset_mass_kg
    kH = vehicle.contact_stiffness_N_per_m
    np.testing.assert_allclose(kH * d[6:], (Mc / 4 + Mt / 2 + Mw) * g, rtol=1e-10)
    Ks, Kp = vehicle.secondary_stiffness_N_per_m, vehicle.primary_stiffness_N_per_m
    np.testing.assert_allclose(Ks * (d[0] - d[2]), Mc * g / 2, rtol=1e-10)
    np.testing.assert_allclose(Kp * (d[2] - d[6]), (Mc / 4 + Mt / 2) * g, rtol=1e-10)
    assert abs(d[1]) < 1e-12 and abs(d[3]) < 1e-12          # symmetric vehicle does not pitch


def test_contact_stiffness_from_hertz(vehicle):
    G = 3.86 * 0.4575 ** (-0.115) * 1e-8
    P0 = (38500 + 2 * 2980 + 4 * 1350) * 9.8 / 8            # total weight on eight wheels
    assert vehicle.static_wheel_load_N == pytest.approx(P0)
    assert vehicle.contact_stiffness_N_per_m == pytest.approx(2 * 1.5 / G * P0 ** (1 / 3))
    assert vehicle.contact_stiffness_N_per_m == pytest.approx(
        2 * contact.linearised_stiffness(P0, contact.hertz_constant(0.4575)))


def test_state_space_in_paper_order(vehicle, model):
    assert vertical_10dof.STATE_NAMES[:4] == ("z_c", "z_c_dot", "beta_c", "beta_c_dot")
    assert vertical_10dof.STATE_NAMES[12] == "z_w1"
    A, B = model.A, model.B
    Minv = np.linalg.inv(model.M)
    np.testing.assert_allclose(A[1::2, 0::2], -Minv @ model.K)
    np.testing.assert_allclose(A[1::2, 1::2], -Minv @ model.C)
    np.testing.assert_allclose(A[0::2, 1::2], np.eye(10))
    kH, Mw = vehicle.contact_stiffness_N_per_m, vehicle.wheelset_mass_kg
    expected_B = np.zeros((20, 4))
    expected_B[[13, 15, 17, 19], [0, 1, 2, 3]] = kH / Mw
    np.testing.assert_allclose(B, expected_B)
    np.testing.assert_array_equal(model.L @ np.arange(20), [12, 14, 16, 18])


def test_paper_C_rows_after_correction(vehicle, model):
    """The paper's C (accelerations), row 1 with −2K_s/M_c and row 3 shifted to the wheelset columns."""
    Ks, Cs, Kp, Cp = (vehicle.secondary_stiffness_N_per_m, vehicle.secondary_damping_Ns_per_m,
                      vehicle.primary_stiffness_N_per_m, vehicle.primary_damping_Ns_per_m)
    Mc, Mt, lc = vehicle.car_body_mass_kg, vehicle.bogie_mass_kg, vehicle.half_bogie_spacing_m
    Ca = model.output_matrix("accelerations")
    row1 = np.zeros(20)
    row1[[0, 1, 4, 5, 8, 9]] = [-2 * Ks / Mc, -2 * Cs / Mc, Ks / Mc, Cs / Mc, Ks / Mc, Cs / Mc]
    np.testing.assert_allclose(Ca[0], row1)
    row3 = np.zeros(20)
    row3[[0, 1, 2, 3, 4, 5, 12, 13, 14, 15]] = [
        Ks / Mt, Cs / Mt, -Ks * lc / Mt, -Cs * lc / Mt, -(Ks + 2 * Kp) / Mt, -(Cs + 2 * Cp) / Mt,
        Kp / Mt, Cp / Mt, Kp / Mt, Cp / Mt]
    np.testing.assert_allclose(Ca[2], row3)
    assert np.all(model.B[[1, 3, 5, 7, 9, 11]] == 0)      # no direct track feedthrough
    both = model.output_matrix("both")
    assert both.shape == (12, 20) and np.linalg.matrix_rank(both) == 12
    with pytest.raises(ValueError):
        model.output_matrix("strain")


def test_modal_table(vehicle, model):
    table = vertical_10dof.modal_table(model)
    assert len(table) == 10
    # body modes near 1.4-1.5 Hz, bogie modes near 6.5-8 Hz (bounce overdamped), wheelsets 229 Hz
    assert set(table["mode"][:2]) == {"car-body bounce", "car-body pitch"}
    assert table["undamped_Hz"][:2].between(1.2, 1.7).all()
    assert table[table["mode"].str.startswith("bogie bounce")]["damping_ratio"].gt(1.0).all()
    kH, Kp, Mw = (vehicle.contact_stiffness_N_per_m, vehicle.primary_stiffness_N_per_m,
                  vehicle.wheelset_mass_kg)
    wheel_hz = np.sqrt((kH + Kp) / Mw) / (2 * np.pi)         # wheelset on its two springs
    np.testing.assert_allclose(table["undamped_Hz"][6:], wheel_hz, rtol=1e-3)
    # the bogie-pitch modes involve only bogie pitch and the wheelsets: closed form check
    Jt, lt = vehicle.bogie_pitch_inertia_kg_m2, vehicle.half_wheelbase_m
    w2 = np.linalg.eigvals(np.linalg.solve(
        np.diag([Jt, Mw, Mw]), np.array([[2 * Kp * lt**2, Kp * lt, -Kp * lt],
                                         [Kp * lt, Kp + kH, 0], [-Kp * lt, 0, Kp + kH]])))
    pitch = table[table["mode"].str.startswith("bogie pitch")]
    np.testing.assert_allclose(pitch["undamped_Hz"], np.sqrt(np.min(w2.real)) / (2 * np.pi), rtol=1e-9)
    # ... and with damping (Eqs. 4, 7, 8: C_p at arm l_t): the bogie-pitch subsystem is exact
    Cp = vehicle.primary_damping_Ns_per_m
    Ms, Ks = np.diag([Jt, Mw, Mw]), np.array([[2 * Kp * lt**2, Kp * lt, -Kp * lt],
                                              [Kp * lt, Kp + kH, 0], [-Kp * lt, 0, Kp + kH]])
    Cs = np.array([[2 * Cp * lt**2, Cp * lt, -Cp * lt], [Cp * lt, Cp, 0], [-Cp * lt, 0, Cp]])
    A3 = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.linalg.solve(Ms, Ks), -np.linalg.solve(Ms, Cs)]])
    slow = sorted(np.linalg.eigvals(A3), key=abs)[:2]          # the bogie-pitch pair (or reals)
    if abs(slow[0].imag) > 0:                                   # underdamped: ζ = −Re λ / |λ|
        np.testing.assert_allclose(pitch["damping_ratio"], -slow[0].real / abs(slow[0]), rtol=1e-6)
    else:                                                       # overdamped: ζ > 1
        assert pitch["damping_ratio"].gt(1.0).all()


def test_loader_rejects_missing_key(tmp_path):
    text = (vertical_10dof.data_path("partial-state-observer/parameters.toml")).read_text()
    head, rest = text.split("[wheel_radius_m]")
    path = tmp_path / "p.toml"
    path.write_text(head + "[gravity_m_per_s2]" + rest.split("[gravity_m_per_s2]")[1])
    with pytest.raises(DataError, match="missing key 'wheel_radius_m'"):
        vertical_10dof.load_parameters(path)
