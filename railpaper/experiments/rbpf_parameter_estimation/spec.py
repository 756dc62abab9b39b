"""The parameters of chapter ``rbpf-parameter-estimation`` (Ding et al. 2014): :data:`SPEC` and
its typed settings, :class:`Settings`.

Kept apart from :mod:`railpaper.experiments.rbpf_parameter_estimation.experiment` (which re-exports it) so
that the chapter's computation stays short; every name, default, quick value and unit is here.
"""

from __future__ import annotations

from railpaper.experiments.base import ChapterSpec, Parameter
from railpaper.experiments.lateral_vehicle import TRACK_AND_SENSORS

#: RBPF particles at which the ledger judges the paper's RBPF, on the toy and the lateral model
#: (the studies ``*_judged_particles``): the paper prints no count, and the only RBPF particle
#: count the book prints is paper 004's, N = 1000, on its own toy (blind policy, two readers:
#: data/rbpf-parameter-estimation/blind/particles_reply.md, particles2_reply.md).
#: ``toy_particles`` and ``n_particles`` are our cheaper counts, shown beside it.  A constant of
#: the ledger, not a setting: the evidence store keys rows by the settings, and a setting no
#: other study reads would re-key every stored study.
JUDGED_PARTICLES = 1000
#: Records of each judged study that were looked at before the count was fixed (a check of the
#: verdicts' sensitivity to the count, at 1000 particles, on the first 30 toy and lateral
#: records): the judged studies start after them, so that no record seen before the policy
#: decides a row (a cold referee's finding).
SEEN_RECORDS = 30


def after_the_seen_records(settings) -> int:
    """The first record of a judged study: the chapter's first seed plus
    :data:`SEEN_RECORDS`."""
    return int(settings.seed) + SEEN_RECORDS

P = Parameter
SPEC = ChapterSpec(
    name="rbpf-parameter-estimation",
    title="RBPF versus EKF for suspension parameters of a high-speed train (Ding et al. 2014)",
    paper="003_106973ea68498aa8.txt",
    notebook="rbpf_parameter_estimation.ipynb",
    quick_sizes="toy: 40 records (full: 300) x 500 steps, 300 particles, IBIS with 1000 "
                "particles on 40 of them (full: 90); lateral: 5 records (full: 30, plus 80 with "
                "the paper scheme alone and 40 with the working scheme alone) x 500 steps, 200 "
                "particles, both schemes, one EKF guess each (10 on the illustrated record), "
                "IBIS on 5 (full: 30) with 100 (250) particles; model error: 5 (20) records",
    notebook_requires={"lateral": True},
    parameters=[
        P("seed", 0, "int", "first Monte Carlo record: records seed, seed + 1 and so on (toy and "
          "lateral); record seed is the one illustrated", minimum=0),
        P("toy_x1", -0.4, "float", "true x1 of Eq. (18), 1"),
        P("toy_x2", 0.5, "float", "true x2 of Eq. (18), 1"),
        P("toy_x3", 0.5, "float", "true x3 of Eq. (18), 1"),
        P("toy_x4", 1.0, "float", "true x4 of Eq. (18), 1"),
        P("toy_noise_var", 0.1, "float", "variance of W and V in Eq. (18), 1", positive=True),
        P("toy_steps", 500, "int", "measurements of each toy record", minimum=10),
        P("toy_particles", 300, "int", "RBPF particles (toy)", minimum=2),
        P("toy_seeds", 300, "int", "toy records (Monte Carlo samples of the toy's claims, < 1000)",
          quick=40, minimum=1, changes_records=False),
        P("toy_prior_halfwidth", 2.0, "float",
          "RBPF prior: uniform on initial condition +- this, per parameter, 1", positive=True),
        P("toy_tempering_steps", 50, "int", "toy working-scheme RBPF: tempering steps",
          minimum=0),
        P("toy_ess_fraction", 0.8, "float", "toy working-scheme RBPF: resample when ESS < this "
          "N, 1", positive=True),
        P("toy_ekf_q_theta", 1e-6, "float", "EKF random-walk variance of each x_j per step, 1",
          positive=True),
        P("toy_bias_tol", 0.2, "float", "toy: a filter has converged when its final |error| is "
          "at most this in every x_j (and, for 'faster', stays so), 1", positive=True),
        P("speed_kmh", 300.0, "float", "vehicle speed, km/h", positive=True),
        P("n_steps", 500, "int", "filter steps of each lateral record (at dt_s); the 350-step "
          "claim is checked from step 350 to this", minimum=400),
        P("dt_s", 0.001, "float", "filter sample time, s", positive=True),
        P("truth_substeps", 10, "int", "truth steps per filter step (truth dt = dt_s / this)",
          minimum=1),
        *TRACK_AND_SENSORS,
        P("n_particles", 200, "int", "RBPF particles (lateral)", minimum=2),
        P("prior_low", 0.5, "float", "prior box lower edge, fraction of the true value",
          positive=True),
        P("prior_high", 1.7, "float", "prior box upper edge, fraction of the true value",
          positive=True),
        P("paper_delta", 0.98, "float", "Liu-West delta of the paper scheme, 1", positive=True),
        P("working_delta", 0.9, "float", "Liu-West delta of the working scheme, 1",
          positive=True),
        P("tempering_steps", 300, "int", "working scheme: likelihood tempering steps", minimum=0),
        P("ess_fraction", 0.5, "float", "lateral working scheme: resample when ESS < this N "
          "(0.5 since 2026-12-04, was 0.8: 3.6 times fewer resamplings, non-inferior on 200 "
          "fresh paired records, data/rbpf-parameter-estimation/ess_threshold_paired.csv; see "
          "the chapter), 1", positive=True),
        P("n_records", 30, "int", "lateral records (Monte Carlo samples, < 1000), each filtered "
          "by both RBPF schemes and one EKF guess", quick=5, minimum=2, changes_records=False),
        P("paper_records", 110, "int", "lateral records (seeds seed … seed + paper_records - 1, "
          "< 1000) filtered by the paper-scheme RBPF, the sample of its two claims ('within 5 % "
          "after 350 steps', 'unbiased'); the first n_records of them are the records above, the "
          "rest get the paper scheme alone (fewer than n_records: n_records)", quick=5,
          minimum=2, changes_records=False),
        P("working_records", 70, "int", "lateral records (seeds seed … seed + working_records "
          "- 1, < 1000) filtered by our working-scheme RBPF, the sample of its rows; the first "
          "n_records of them are the records above, the rest get the working scheme alone "
          "(fewer than n_records: n_records)", quick=5, minimum=2, changes_records=False),
        P("ekf_guesses", 10, "int", "initial parameter guesses of the lateral EKF on the "
          "illustrated record (the others get one each)", minimum=1),
        P("ekf_steps", 500, "int", "steps of each lateral EKF run (<= n_steps)", minimum=10),
        P("toy_ibis_particles", 1000, "int", "IBIS particles of the toy's exact posterior "
          "(prior box of initial condition 1)", minimum=10),
        P("toy_ibis_records", 90, "int", "toy records (the first ones, at most toy_seeds) on "
          "which IBIS computes the exact posterior; coverage and the EKF's offset are counted on "
          "them", quick=40, minimum=1, changes_records=False),
        P("ibis_particles", 250, "int", "IBIS particles of the lateral exact posterior",
          quick=100, minimum=10),
        P("ibis_records", 30, "int", "lateral records (the first ones, at most n_records) on "
          "which IBIS computes the exact posterior; calibration is counted on them", quick=5,
          minimum=1, changes_records=False),
        P("mismatch_records", 20, "int", "records (the first seeds, at most n_records) of the "
          "truth plant with model error (saturating creep, nonlinear conicity, 40 Hz "
          "low-pass), each filtered by the EKF and our tempered RBPF", quick=5, minimum=2,
          changes_records=False),
        P("measurements_csv", "", "str",
          "user CSV (t_s, acc_w1_mps2, acc_w2_mps2, acc_b_mps2, acc_bd_mps2, yawrate_b_radps"
          "[, ydot_t1_mps, ydot_t2_mps]) instead of simulated data; empty = simulate",
          path=True),
        P("lateral", True, "bool", "run Part 2, the lateral vehicle (sweep samples of the toy "
          "alone switch it off; the notebook needs it)", changes_records=False),
    ],
)
Settings = SPEC.settings_type

__all__ = ["SPEC", "Settings"]
