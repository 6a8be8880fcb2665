"""seeds/002 (free-gyro positioning): the system (1)-(7), the error chain (8)-(29), the
position error model (30)-(35) and both DOP figures (37); ``dracc fix --gyro-vector``.

Independent values: hand-built geometry for (1)-(4), finite differences of the exact
equations for the linearisations (24), (29) and below (21), a first-order hand solution
of the rate chain, and a Monte Carlo over exact solutions of (1) for the position model.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from dracc.core.distributions import chi2_ppf
from dracc.core.geodesy import A_M, E2, radius_meridian_m, radius_prime_vertical_m
from dracc.math import freegyro as fg
from dracc.math.fusion import OMEGA_E_RADPS, NadirCircle

D = math.radians


def _u(theta_rad, alpha_rad, lat_rad, lon_rad, t_s):
    """The gyro vector with nadir angle theta and azimuth alpha at a position: built from
    the local vertical, north and east in the inertial frame (by hand, not by (1))."""
    big_l = lon_rad + OMEGA_E_RADPS * t_s
    up = np.array(
        [
            math.cos(lat_rad) * math.cos(big_l),
            math.cos(lat_rad) * math.sin(big_l),
            math.sin(lat_rad),
        ]
    )
    north = np.array(
        [
            -math.sin(lat_rad) * math.cos(big_l),
            -math.sin(lat_rad) * math.sin(big_l),
            math.cos(lat_rad),
        ]
    )
    east = np.array([-math.sin(big_l), math.cos(big_l), 0.0])
    horiz = math.cos(alpha_rad) * north + math.sin(alpha_rad) * east
    return -math.cos(theta_rad) * up + math.sin(theta_rad) * horiz


# ------------------------------------------------------------------ (1)-(7)


def test_eq1_eq2_hand_case_at_greenwich_and_equator():
    # at phi = 0, L = 0 the vertical is x, north z, east y: u = (-cos 30, sin 30 sin 60, sin 30 cos 60)
    u = np.array([-math.cos(D(30)), 0.5 * math.sin(D(60)), 0.5 * math.cos(D(60))])
    assert fg.cos_nadir(u, 0.0, 0.0, 0.0) == pytest.approx(math.cos(D(30)), abs=1e-15)  # (1)
    assert fg.gyro_azimuth_rad(u, 0.0, 0.0, 0.0) == pytest.approx(D(60), abs=1e-15)  # (2)
    # the same inertial longitude L reached by time: lambda = -90 deg, omega_e t = 90 deg
    t = D(90) / OMEGA_E_RADPS
    assert fg.nadir_rad(u, 0.0, D(-90), t) == pytest.approx(D(30), abs=1e-12)
    # and (1) is fusion's nadir circle about the sub-point of -u
    c = NadirCircle.from_gyro_vector(u, t, 0.0, 1.0)
    assert c.cos_nadir(D(41.0), D(-70.0)) == pytest.approx(
        fg.cos_nadir(u, D(41.0), D(-70.0), t), abs=1e-14
    )


@pytest.mark.parametrize("alpha_deg", [10.0, 100.0, 200.0, 350.0])
def test_eq2_azimuth_of_a_built_vector(alpha_deg):
    lat, lon, t = D(54.6), D(18.7), 12345.0
    u = _u(D(40.0), D(alpha_deg), lat, lon, t)
    assert fg.gyro_azimuth_rad(u, lat, lon, t) == pytest.approx(D(alpha_deg), abs=1e-12)
    assert fg.nadir_rad(u, lat, lon, t) == pytest.approx(D(40.0), abs=1e-12)


def test_eq3_eq4_heading_hand_values_all_quadrants():
    # phi = 60 deg, psi = 30 deg: omega_Nx = w 0.5 cos 30, omega_Ny = -w 0.5 sin 30 (3)
    wx, wy = fg.spin_rates_radps(D(60), D(30))
    assert wx == pytest.approx(OMEGA_E_RADPS * 0.5 * math.sqrt(3) / 2, rel=1e-12)
    assert wy == pytest.approx(-OMEGA_E_RADPS * 0.25, rel=1e-12)
    for psi_deg in (0.0, 30.0, 135.0, 225.0, 300.0):
        wx, wy = fg.spin_rates_radps(D(35), D(psi_deg))
        assert fg.heading_from_spin_rates_rad(wx, wy) == pytest.approx(D(psi_deg), abs=1e-12)  # (4)
    assert fg.azimuth_from_heading_rad(D(300), D(100)) == pytest.approx(D(40), abs=1e-12)  # (5)
    assert fg.tilt_rate_radps(D(60), D(90)) == pytest.approx(-OMEGA_E_RADPS * 0.5, rel=1e-12)  # (6)


# --------------------------------------------------------------- linearisations


def test_eq29_corrected_sign_is_the_derivative_of_eq4():
    w = np.array(fg.spin_rates_radps(D(50), D(70)) + (0.0,))
    dw = np.array([3e-9, -2e-9, 0.0])
    h = 1e-3  # finite difference of the exact (4) along dw
    fd = (
        fg.heading_from_spin_rates_rad(*(w[:2] + h * dw[:2]))
        - fg.heading_from_spin_rates_rad(*(w[:2] - h * dw[:2]))
    ) / (2 * h)
    assert fg.heading_error_rad(w, dw) == pytest.approx(fd, rel=1e-6)
    # the paper's printed (29), without the minus sign, has the opposite sign
    printed = (w[0] * dw[1] - w[1] * dw[0]) / (w[0] ** 2 / math.cos(D(70)) ** 2)
    assert printed == pytest.approx(-fd, rel=1e-6)


def test_eq24_is_the_derivative_of_the_horizontal_rate():
    w, dw = np.array([3e-5, -4e-5, 1e-5]), np.array([2e-7, 1e-7, 5e-7])
    fd = (np.hypot(*(w + 1e-3 * dw)[:2]) - np.hypot(*(w - 1e-3 * dw)[:2])) / 2e-3
    assert fg.horizontal_rate_error(w, dw) == pytest.approx(fd, rel=1e-9)


def test_nav_rate_error_below_eq21_is_the_derivative_of_omega_in():
    lat, lam_dot = D(40.0), 2e-6

    def omega_in(phi, phi_dot, ld):  # [(ld + w) cos phi, -phi_dot, -(ld + w) sin phi]
        r = ld + OMEGA_E_RADPS
        return np.array([r * math.cos(phi), -phi_dot, -r * math.sin(phi)])

    d = np.array([1e-6, 3e-9, -2e-9])  # d phi, d phi_dot, d lam_dot
    fd = (
        omega_in(lat + d[0], d[1], lam_dot + d[2]) - omega_in(lat - d[0], -d[1], lam_dot - d[2])
    ) / 2
    got = fg.nav_rate_error_radps(lat, lam_dot, d[0], d[1], d[2])
    assert got == pytest.approx(fd, rel=1e-6, abs=1e-20)


def test_skew_and_attitude_equations_19_20_hand_values():
    a, b = np.array([1.0, 2.0, 3.0]), np.array([-2.0, 0.5, 4.0])
    assert fg.skew(a) @ b == pytest.approx(np.cross(a, b))
    # (19) with C = I, zero rate: xi' = -d w_ig + d w_ib
    got = fg.gyro_attitude_error_rate(np.zeros(3), np.zeros(3), np.eye(3), a, b)
    assert got == pytest.approx(b - a)
    # (20): gamma' = -w x gamma - C d w_ib + d w_in
    got = fg.body_attitude_error_rate(a, b, np.eye(3), a, np.zeros(3))
    assert got == pytest.approx(-np.cross(b, a) - a)


# ------------------------------------------------------------- the rate chain


def _stationary(lat, alpha):
    w = np.array([OMEGA_E_RADPS * math.cos(lat), 0.0, -OMEGA_E_RADPS * math.sin(lat)])
    gyro = fg.FreeGyro(np.eye(3), w.copy(), alpha)
    plat = fg.Platform(np.eye(3), w.copy(), w.copy(), np.zeros(3))
    return gyro, plat


def test_spin_sensor_bias_to_nadir_error_first_order_hand_solution():
    """C = I, omega_ig^g = omega_ib^b = omega_in^n = Earth rate, a spin-sensor bias b.
    To first order in omega_e T: d omega_L = b, d zeta = b_z t, d psi = -b_y / (w cos phi),
    so (25)-(26): d theta(T) = (-b_x sin a + b_y cos a) T - w cos phi cos a b_z T^2 / 2."""
    lat, alpha, t = D(45.0), D(30.0), 60.0
    gyro, plat = _stationary(lat, alpha)
    f, g, _, _ = fg.error_model_matrices((gyro,), plat)
    b = np.array([2e-8, -1e-8, 3e-8])
    aug = np.zeros((8 + 6, 8 + 6))
    aug[:8, :8], aug[:8, 8:] = f, g
    x = fg.expm(aug * t)[:8, 8:] @ np.r_[np.zeros(3), b]
    hand = (-b[0] * math.sin(alpha) + b[1] * math.cos(alpha)) * t
    hand -= OMEGA_E_RADPS * math.cos(lat) * math.cos(alpha) * b[2] * t**2 / 2
    assert x[7] == pytest.approx(hand, rel=5e-3)
    # the bias budget says the same with sigma 1e-8 per axis
    bud = fg.nadir_error_budget((gyro,), plat, fg.RateSensorErrors(spin_bias_radps=1e-8), t)
    per_axis = np.array(
        [
            -math.sin(alpha) * t,
            math.cos(alpha) * t,
            -OMEGA_E_RADPS * math.cos(lat) * math.cos(alpha) * t**2 / 2,
        ]
    )
    assert bud.bias_cov_rad2[0, 0] == pytest.approx(1e-16 * np.sum(per_axis**2), rel=1e-2)
    # heading from (29): a north-axis-free bias b_y gives d psi = -b_y / (w cos phi)
    assert bud.heading_sigma_rad[0] == pytest.approx(
        1e-8 / (OMEGA_E_RADPS * math.cos(lat)), rel=2e-2
    )


def test_spin_sensor_noise_is_an_angle_random_walk_and_body_errors_cancel():
    lat, t = D(45.0), 120.0
    gyro, plat = _stationary(lat, D(75.0))
    noise = fg.nadir_error_budget((gyro,), plat, fg.RateSensorErrors(spin_noise_rad_rts=1e-6), t)
    # first order: d theta' = -dw_x sin a + dw_y cos a -> variance N^2 T
    assert noise.noise_cov_rad2[0, 0] == pytest.approx(1e-12 * t, rel=1e-2)
    # a body-rate error moves gyro and body frames alike ((19) and (20) cancel in (22))
    body = fg.nadir_error_budget(
        (gyro,), plat, fg.RateSensorErrors(body_bias_radps=1e-8, body_noise_rad_rts=1e-6), t
    )
    assert body.cov_theta_rad2[0, 0] < 1e-4 * noise.noise_cov_rad2[0, 0]


def test_noise_covariance_matches_a_simulation_of_the_linear_model():
    """Van Loan's discrete covariance against an Euler simulation of x' = F x + G w."""
    lat, t, steps, runs = D(30.0), 300.0, 300, 4000
    g1, plat = _stationary(lat, D(20.0))
    g2 = fg.FreeGyro(np.eye(3), g1.omega_ig_g_radps, D(120.0))
    err = fg.RateSensorErrors(spin_noise_rad_rts=1e-6, body_noise_rad_rts=2e-6)
    bud = fg.nadir_error_budget((g1, g2), plat, err, t)
    f, g = bud.f, bud.g
    q = np.r_[np.full(3, 4e-12), np.full(6, 1e-12)]
    rng = np.random.default_rng(21)
    dt = t / steps
    x = np.zeros((runs, f.shape[0]))
    for _ in range(steps):
        w = rng.normal(size=(runs, 9)) * np.sqrt(q / dt)
        x = x + dt * (x @ f.T + w @ g.T)
    sample = np.cov(x[:, [7, 12]].T)
    for i in range(2):  # chi-square bound on each variance (runs - 1 degrees of freedom)
        ratio = (runs - 1) * sample[i, i] / bud.noise_cov_rad2[i, i]
        assert chi2_ppf(0.0005, runs - 1) < ratio < chi2_ppf(0.9995, runs - 1)


# ---------------------------------------------------- (30)-(35): Monte Carlo over (1)


def _solve_exact(u, t, cos_theta, lat0, lon0):
    """Newton on the two equations (1) (finite-difference Jacobian), batched over runs."""
    lat, lon = np.full(len(t), lat0), np.full(len(t), lon0)

    def f(la, lo):
        return np.stack([fg.cos_nadir(u[:, k], la, lo, t) for k in range(2)], axis=-1) - cos_theta

    for _ in range(8):
        h = 1e-7
        r = f(lat, lon)
        j = np.stack(
            [
                (f(lat + h, lon) - f(lat - h, lon)) / (2 * h),
                (f(lat, lon + h) - f(lat, lon - h)) / (2 * h),
            ],
            axis=-1,
        )
        step = np.linalg.solve(j, r[..., None])[..., 0]
        lat, lon = lat - step[:, 0], lon - step[:, 1]
    assert np.max(np.abs(f(lat, lon))) < 1e-13
    return lat, lon


def test_monte_carlo_over_exact_solutions_of_eq1_matches_the_linear_model():
    rng = np.random.default_rng(2002)
    n = 3000
    lat, lon, t0 = D(35.1), D(129.05), 7200.0
    u_true = np.stack([_u(D(35.0), D(20.0), lat, lon, t0), _u(D(60.0), D(115.0), lat, lon, t0)])
    theta = fg.nadir_rad(u_true, lat, lon, t0)
    s_u, s_t = 1e-4, 3.0
    cov_theta = np.array([[4e-8, 1.2e-8], [1.2e-8, 9e-8]])  # correlated nadir errors
    # perturbed inputs: the gyro vectors rotated by small random angles, the nadir angles
    # and one clock error; the true position then solves (1) with the true inputs, the
    # estimate with the perturbed ones
    eps = rng.normal(scale=s_u, size=(n, 2, 3))
    u_meas = u_true + np.cross(eps, u_true)
    u_meas /= np.linalg.norm(u_meas, axis=-1, keepdims=True)
    d_theta = rng.multivariate_normal(np.zeros(2), cov_theta, size=n)
    t_meas = t0 + rng.normal(scale=s_t, size=n)
    est_lat, est_lon = _solve_exact(u_meas, t_meas, np.cos(theta + d_theta), lat, lon)
    err = np.stack(
        [
            (est_lat - lat) * radius_meridian_m(lat),
            (est_lon - lon) * radius_prime_vertical_m(lat) * math.cos(lat),
        ],
        axis=-1,
    )
    rows = fg.position_rows(u_true, lat, lon, t0)
    cov_z = fg.z_covariance(rows, cov_theta, s_u, s_t)
    _, p = fg.position_covariance(rows, cov_z, lat)
    # (33) in closed form: Psi^-1 cov(Z) Psi^-T
    inv = np.linalg.inv(rows.psi)
    s = fg.metric_scale(lat)
    assert p == pytest.approx(s @ inv @ cov_z @ inv.T @ s, rel=1e-10)
    nees = np.einsum("ni,ij,nj->n", err, np.linalg.inv(p), err)
    assert chi2_ppf(0.0005, 2 * n) < nees.sum() < chi2_ppf(0.9995, 2 * n)
    sample = np.cov(err.T)
    for i in range(2):
        ratio = (n - 1) * sample[i, i] / p[i, i]
        assert chi2_ppf(0.0005, n - 1) < ratio < chi2_ppf(0.9995, n - 1)
    inside = np.mean(nees <= chi2_ppf(0.95, 2))
    assert abs(inside - 0.95) < 3.3 * math.sqrt(0.95 * 0.05 / n)  # binomial bound
    assert abs(np.mean(err, axis=0)).max() < 4 * math.sqrt(np.diag(p).max() / n)


# --------------------------------------------------------------------- DOP (37)


def test_fdop_printed_and_trace_hand_values_equal_nadirs():
    # phi = 0, L = 0, alpha 0 and 90 deg, theta 30 deg: Psi = -sin(theta) I, Q = I / sin^2
    us = np.stack([_u(D(30), 0.0, 0.0, 0.0, 0.0), _u(D(30), D(90), 0.0, 0.0, 0.0)])
    d = fg.dop_figures(us, 0.0, 0.0, 0.0)
    assert d.cofactor_rad2 == pytest.approx(np.eye(2) * 4.0, abs=1e-12)
    assert d.fdop_printed == pytest.approx(4.0 * math.sqrt(2.0), rel=1e-12)  # (37) as printed
    assert d.dop == pytest.approx(math.sqrt(2.0), rel=1e-12)  # trace, orthogonal unit rows
    # (35) with one sigma_s: diag(R_M^2, R_N^2) / (R_M R_N) at the equator, by hand
    r_m, r_n = A_M * (1 - E2), A_M
    assert d.dop_paper == pytest.approx(math.sqrt((r_m**2 + r_n**2) / (r_m * r_n)), rel=1e-12)
    assert d.dop_paper == pytest.approx(d.dop_model, rel=1e-12)  # theta_a = theta_b


@pytest.mark.parametrize("theta_b_deg", [20.0, 45.0, 70.0, 88.0])
def test_dops_equal_when_nadirs_equal_and_differ_as_documented_when_not(theta_b_deg):
    lat, lon, t = D(54.6), D(18.7), 500.0
    theta_a = D(45.0)
    us = np.stack([_u(theta_a, D(10), lat, lon, t), _u(D(theta_b_deg), D(100), lat, lon, t)])
    d = fg.dop_figures(us, lat, lon, t)
    assert d.dop_model == pytest.approx(d.dop, rel=7e-3)  # equal sigma_theta: within flattening
    sa2, sb2 = math.sin(theta_a) ** 2, math.sin(D(theta_b_deg)) ** 2
    # docs/free-gyro.md: circles crossing at right angles, ratio^2 = mean(s^2) mean(1/s^2)
    ratio = math.sqrt((sa2 + sb2) / 2 * (1 / sa2 + 1 / sb2) / 2)
    assert d.dop_paper / d.dop_model == pytest.approx(ratio, rel=1e-2)
    if theta_b_deg == 45.0:
        assert d.dop_paper == pytest.approx(d.dop_model, rel=1e-12)
    else:
        assert d.dop_paper > 1.01 * d.dop_model
    # (37) as printed is not a DOP of metres: it changes with the unit of the angles
    q_deg = d.cofactor_rad2 * (180 / math.pi) ** 2
    assert math.hypot(q_deg[0, 0], q_deg[1, 1]) == pytest.approx(
        d.fdop_printed * (180 / math.pi) ** 2
    )


# ------------------------------------------------------------------------ CLI


def _gyro_args(lat, lon, t, sigma="0.01,0.005,2"):
    args = []
    for theta, alpha in ((D(35.0), D(20.0)), (D(60.0), D(115.0))):
        u = _u(theta, alpha, lat, lon, t)
        args += [
            "--gyro-vector",
            f"{u[0]:.13f},{u[1]:.13f},{u[2]:.13f},{t},{math.degrees(theta):.10f},{sigma}",
        ]
    return args


def test_cli_gyro_vectors_fix_json_and_toml(run_cli, tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    from dracc.report.fix_report import JSON_SCHEMA

    lat, lon, t = D(35.1), D(129.05), 7200.0
    args = _gyro_args(lat, lon, t)
    code, out, err = run_cli("fix", *args, "--prior", "35,129", "--json", "-")
    assert code == 0, err
    j = json.loads(out)
    jsonschema.validate(j, JSON_SCHEMA)
    assert j["lat_deg"] == pytest.approx(35.1, abs=1e-8) and j["lon_deg"] == pytest.approx(
        129.05, abs=1e-8
    )
    fgj = j["free_gyro"]
    assert fgj["gyro_vectors"] == ["gyro vector 1", "gyro vector 2"]
    assert fgj["dop_trace"] == pytest.approx(j["dop"], rel=1e-6)
    u = np.stack([_u(D(35.0), D(20.0), lat, lon, t), _u(D(60.0), D(115.0), lat, lon, t)])
    rows = fg.position_rows(u, lat, lon, t)
    _, p = fg.position_covariance(
        rows, fg.z_covariance(rows, np.eye(2) * D(0.01) ** 2, D(0.005), 2.0), lat
    )
    assert np.array(fgj["cov_m2"]) == pytest.approx(p, rel=1e-5)
    # with sigma_u = sigma_t = 0 the model's covariance is the WLS fix's (W3)
    code, out, _ = run_cli(
        "fix", *_gyro_args(lat, lon, t, "0.01"), "--prior", "35,129", "--json", "-"
    )
    j0 = json.loads(out)
    assert np.array(j0["free_gyro"]["cov_m2"]) == pytest.approx(np.array(j0["cov_m2"]), rel=1e-3)
    # the observation file's [[gyro_vector]] gives the same
    keys = ("ux", "uy", "uz", "time_s", "nadir_deg", "sigma_deg", "sigma_u_deg", "sigma_t_s")
    text = "[prior]\nlat = 35\nlon = 129\n"
    for i in range(1, len(args), 2):
        vals = args[i].split(",")
        text += "[[gyro_vector]]\n" + "".join(
            f"{k} = {v}\n" for k, v in zip(keys, vals, strict=True)
        )
    obs = tmp_path / "obs.toml"
    obs.write_text(text)
    code, out, err = run_cli("fix", "--file", obs, "--json", "-")
    assert code == 0, err
    jf = json.loads(out)
    assert jf["lat_deg"] == pytest.approx(j["lat_deg"], abs=1e-12)
    assert np.array(jf["free_gyro"]["cov_m2"]) == pytest.approx(np.array(fgj["cov_m2"]), rel=1e-12)
    # the tables name both figures
    code, out, _ = run_cli("fix", *args, "--prior", "35,129")
    assert code == 0 and "FDOP (37) printed" in out and "DOP, trace form" in out


def test_cli_gyro_vector_errors(run_cli):
    code, _, err = run_cli(
        "fix", "--gyro-vector", "0.5,0.5,0.5,0,30", "--gyro-vector", "0,0,1,0,30", "--prior", "0,0"
    )
    assert code == 2 and "--gyro-vector" in err and "unit vector" in err and "Traceback" not in err
    code, _, err = run_cli("fix", "--gyro-vector", "0,0,1,0,30")
    assert code == 2 and "--prior" in err
    code, _, err = run_cli("fix", "--gyro-vector", "0,0,1,0,190", "--prior", "0,0")
    assert code == 2 and "NADIR_DEG" in err
