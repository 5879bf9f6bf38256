#include "estimators/nav_filter.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "core/earth.hpp"
#include "core/table.hpp"
#include "core/units.hpp"
#include "estimators/direct_calibration.hpp"
#include "estimators/thermal.hpp"

namespace imucal::navfilter {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using namespace state;

namespace {

template <int Rows, int Cols>
using Mat = Eigen::Matrix<double, Rows, Cols>;

// d(delta_D w)/d(angles) for the gyro angles in the order xy xz yx yz zx zy (rows: sensor axes).
Mat<3, 6> gyro_angle_jacobian(const Vector3d& w) {
  Mat<3, 6> J = Mat<3, 6>::Zero();
  J(0, 0) = -w.z();  // xy
  J(0, 1) = w.y();   // xz
  J(1, 2) = w.z();   // yx
  J(1, 3) = -w.x();  // yz
  J(2, 4) = -w.y();  // zx
  J(2, 5) = w.x();   // zy
  return J;
}

// The same for the accelerometer non-orthogonalities yz zx zy (x is the body reference); row j
// of f_channels is the specific force at accelerometer j's proof mass.
Mat<3, 3> accel_angle_jacobian(const Matrix3d& f_channels) {
  Mat<3, 3> J = Mat<3, 3>::Zero();
  J(1, 0) = -f_channels(1, 0);  // yz
  J(2, 1) = -f_channels(2, 1);  // zx
  J(2, 2) = f_channels(2, 0);   // zy
  return J;
}

// The gyro angle states in the order of kMisalignmentKeys.
constexpr std::array<double Misalignment::*, 6> kGyroAngleKeys = {
    kMisalignmentKeys[0].member, kMisalignmentKeys[1].member, kMisalignmentKeys[2].member,
    kMisalignmentKeys[3].member, kMisalignmentKeys[4].member, kMisalignmentKeys[5].member};
constexpr std::array<double Misalignment::*, 3> kAccelAngleKeys = {&Misalignment::yz, &Misalignment::zx,
                                                                   &Misalignment::zy};

template <class V>
auto seg(V& v, const Block& b) {
  return v.segment(b.index, b.size);
}

using ConsiderMatrix = Eigen::Matrix<double, kSize, Eigen::Dynamic>;

// The navigation error's states: the only rows of F that are not zero (propagate()).
constexpr int kNav = kFirstCalibration;
static_assert(kAttitude.index == 0 && kVelocity.index == 3 && kPosition.index + kPosition.size == kNav);
using NavRows = Eigen::Matrix<double, kNav, kSize>;

}  // namespace

StateVector model_to_state(const ImuModel& m) {
  StateVector x = StateVector::Zero();
  seg(x, kGyroBias) = m.gyro.bias_radps;
  seg(x, kAccelBias) = m.accel.bias_mps2;
  seg(x, kGyroScalePos) = m.gyro.scale_pos;
  seg(x, kGyroScaleNeg) = m.gyro.scale_neg;
  seg(x, kAccelScale) = m.accel.scale;
  for (int i = 0; i < 6; ++i) x[kGyroAngles.index + i] = m.gyro.misalignment_rad.*kGyroAngleKeys[static_cast<std::size_t>(i)];
  for (int i = 0; i < 3; ++i) x[kAccelAngles.index + i] = m.accel.misalignment_rad.*kAccelAngleKeys[static_cast<std::size_t>(i)];
  seg(x, kGyroDelay) = m.gyro.delay_s;
  seg(x, kAccelDelay) = m.accel.delay_s;
  const Matrix3d offsets = proof_mass_offsets_m(m);  // in the model's frame, as the filter sees them
  seg(x, kLeverArmY) = offsets.col(1);
  seg(x, kLeverArmZ) = offsets.col(2);
  seg(x, kBodyAlignment) = m.body_to_instrument_rad.value_or(Vector3d::Zero());
  return x;
}

struct NavCalibrationFilter::Impl {
  RecordingMeta meta;
  Options opt;
  ImuModel model;  // body frame, updated by feedback; with a thermal section: the values at T_ref
  ImuModel model_at_start;
  // What the compensator applies: `model`, moved to the current temperatures by the thermal
  // section. A temperature change of an angle is the same relative to o or to the body frame
  // (fixed at T_ref), so the section's additive polynomials apply to the body-frame values as they
  // are; the accelerometer's xy, xz, yx then leave zero, which the compensator handles.
  ImuModel compensated;
  std::optional<thermal::ThermalSection> thermal_section;
  thermal::ChannelRate temp_rate;
  bool have_temps = false;
  nav::Compensator comp;
  nav::TableReference ref;
  double dt_nominal_s;
  double g_mps2;
  std::deque<ImuFrame> window;
  std::unique_ptr<nav::Strapdown> nav;

  // The type B sources as consider parameters (Options::type_b), each in units of its 1-sigma (their
  // covariance is the identity): the budget source each counts under, the table's kinematics with
  // it moved by its sigma (none for the site's g), and Pxp, the state's covariance with them. Their
  // values never change (a Schmidt filter), so what the state learns of them stays in Pxp.
  struct Consider {
    std::vector<std::string> source;
    std::vector<std::optional<table::TableKinematics>> moved_table;
    table::TableKinematics table;  // the recording's, as the reference applies it
    int gravity = -1;              // the column of the site's g, if considered
    double gravity_sigma_mps2 = 0;
    ConsiderMatrix Pxp;
    // The start model's terms the filter compensates with and does not estimate (their sigma from
    // the start model): they drive the attitude (gyro) or the velocity (accelerometers).
    struct StartTerm {
      enum Kind { kGyroScaleNonlinear, kGyroGSensitivity, kAccelK2, kAccelK3 } kind;
      int column, j, k;  // channel j; k: the power's index (c1 c2 c3) or the force's axis
      double sigma;
    };
    std::vector<StartTerm> start_terms;
    int size() const { return static_cast<int>(source.size()); }
    void add(const std::string& name) {
      source.push_back(name);
      moved_table.emplace_back(std::nullopt);
    }
  } consider;
  // Over the propagation interval, for the start terms: column 3 (m-1) + j the integral of
  // C_b_n[:, j] q_j^m w_j (gyro j's nonlinearity of power m); column 3 j + k that of C_b_n[:, j]
  // f_k / g_std (g-sensitivity); column j that of C_b_n[:, j] a_j f_j and 3 + j of C_b_n[:, j] a_j^2
  // f_j, a_j = f_j / g_std (K2, K3).
  Mat<3, 9> S_Cq = Mat<3, 9>::Zero(), S_Cfg = Mat<3, 9>::Zero();
  Mat<3, 6> S_Ca = Mat<3, 6>::Zero();

  StateVector x = StateVector::Zero();
  StateMatrix P = StateMatrix::Zero();
  StateVector sigma0;

  // Integrals over the current propagation interval of the time-varying parts of F.
  Matrix3d S_C = Matrix3d::Zero(), S_Cwp = Matrix3d::Zero(), S_Cwn = Matrix3d::Zero();
  Matrix3d S_Cwdot = Matrix3d::Zero(), S_Cf = Matrix3d::Zero(), S_Cfdot = Matrix3d::Zero();
  Matrix3d S_fn = Matrix3d::Zero(), S_CMa = Matrix3d::Zero();
  Mat<3, 6> S_CMg = Mat<3, 6>::Zero();
  Matrix3d S_CKy = Matrix3d::Zero(), S_CKz = Matrix3d::Zero();  // proof-mass offsets y, z
  double S_dt = 0;
  double since_update_s = 0;
  Vector3d prev_f = Vector3d::Zero();
  bool have_prev_rates = false;
  bool stopped = false;
  std::size_t next_restart = 0;
  std::vector<double> restart_times_s;
  double next_history_s = 0;
  int consecutive_rejections = 0;
  Result result;
  double t_s = 0;

  Impl(const RecordingMeta& m, const ImuModel& model_in, const Options& o)
      : meta(m),
        opt(o),
        model(model_in.frame == "body" ? model_in : direct::to_body_frame(model_in)),
        compensated(model),
        comp(compensated, 1.0 / m.rate_hz, o.max_delay_s),
        ref(m, model),
        dt_nominal_s(1.0 / m.rate_hz),
        g_mps2(earth::site_gravity_mps2(m.site)),
        consider{{}, {}, table_kinematics(m), -1, 0.0, ConsiderMatrix(kSize, 0), {}} {
    if (o.type_b) {
      // Stage 1's list of the reference's type B sources, read here for the table's attitude and g.
      const double gravity_sigma_mps2 = o.gravity_sigma_mps2.value_or(earth::site_gravity_sigma_mps2(m.site));
      for (const direct::ReferencePerturbation& p : direct::reference_perturbations(m, gravity_sigma_mps2)) {
        if (p.source == "site.gravity_mps2") {
          consider.add(p.source);
          consider.gravity = consider.size() - 1;
          consider.gravity_sigma_mps2 = gravity_sigma_mps2;
        } else {
          consider.source.push_back(p.source);
          consider.moved_table.emplace_back(table_kinematics(p.meta));
        }
      }
      add_start_terms(model.sigma.value_or(ImuErrorSet{}));
      consider.Pxp = ConsiderMatrix::Zero(kSize, consider.size());
    }
    model_at_start = model;
    if (auto section = thermal::thermal_of(model); section && section->has_models()) thermal_section = *section;
    for (const SegmentInfo& s : m.segments)
      if ((s.kind == "static" || s.kind == "tilt") && s.t1_s - s.t0_s >= o.restart_static_s)
        restart_times_s.push_back(s.t0_s);
    std::sort(restart_times_s.begin(), restart_times_s.end());
    StateVector s0;
    seg(s0, kAttitude).setConstant(o.sigma_attitude_rad);
    seg(s0, kVelocity).setConstant(o.sigma_velocity_mps);
    seg(s0, kPosition).setConstant(o.sigma_position_m);
    seg(s0, kGyroBias).setConstant(o.sigma_gyro_bias_radps);
    seg(s0, kAccelBias).setConstant(o.sigma_accel_bias_mps2);
    seg(s0, kGyroScalePos).setConstant(o.sigma_gyro_scale);
    seg(s0, kGyroScaleNeg).setConstant(o.sigma_gyro_scale);
    seg(s0, kAccelScale).setConstant(o.sigma_accel_scale);
    seg(s0, kGyroAngles).setConstant(o.sigma_gyro_angle_rad);
    seg(s0, kAccelAngles).setConstant(o.sigma_accel_angle_rad);
    seg(s0, kGyroDelay).setConstant(o.sigma_gyro_delay_s);
    seg(s0, kAccelDelay).setConstant(o.sigma_accel_delay_s);
    seg(s0, kLeverArmY).setConstant(o.sigma_lever_arm_m);
    seg(s0, kLeverArmZ).setConstant(o.sigma_lever_arm_m);
    seg(s0, kBodyAlignment).setConstant(o.sigma_body_alignment_rad);
    if (model.sigma) {
      seg(s0, kLeverArmY) = seg(s0, kLeverArmY).cwiseMax(model.sigma->accel.lever_arm_y_m);
      seg(s0, kLeverArmZ) = seg(s0, kLeverArmZ).cwiseMax(model.sigma->accel.lever_arm_z_m);
    }
    if (model_in.sigma && model_in.frame == "instrument") {
      // to_body_frame: the rotation is (yx, xy, xz) of the instrument-frame accelerometer angles.
      const Misalignment& sa = model_in.sigma->accel.misalignment_rad;
      seg(s0, kBodyAlignment) = seg(s0, kBodyAlignment).cwiseMax(Vector3d(sa.yx, sa.xy, sa.xz));
    }
    sigma0 = s0;
    P = s0.cwiseAbs2().asDiagonal();
    result.sigma0 = s0;
  }

  void add_start_terms(const ImuErrorSet& start_sigma) {
    using Term = Consider::StartTerm;
    namespace src = direct::start_model_source;
    auto add = [&](const char* source, Term::Kind kind, int j, int k, double sigma) {
      if (!(sigma > 0)) return;
      consider.add(source);
      consider.start_terms.push_back({kind, consider.size() - 1, j, k, sigma});
    };
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) {
        add(src::kGyroScaleNonlinear, Term::kGyroScaleNonlinear, j, k, start_sigma.gyro.scale_nonlinear(j, k));
        add(src::kGyroGSensitivity, Term::kGyroGSensitivity, j, k, start_sigma.gyro.g_sensitivity_radps_per_g(j, k));
      }
    for (int j = 0; j < 3; ++j) {
      add(src::kAccelK2, Term::kAccelK2, j, 0, start_sigma.accel.k2_per_g[j]);
      add(src::kAccelK3, Term::kAccelK3, j, 0, start_sigma.accel.k3_per_g2[j]);
    }
  }

  // How the table's attitude at these encoder angles moves (a rotation vector in n, rad) when each
  // consider parameter moves by its sigma: column j. The rotation from the platform to the body
  // frame is the same on both sides and cancels. Zero for the site's g. The velocity and position
  // the table implies move too (the origin's offset turned by the error), by well under a micron
  // for a few arc seconds: left out.
  Eigen::Matrix<double, 3, Eigen::Dynamic> table_attitude_sensitivity(const ImuFrame& f) const {
    Eigen::Matrix<double, 3, Eigen::Dynamic> G = Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, consider.size());
    const Vector3d encoder_rad = f.table_deg * units::kDegToRad;
    const Matrix3d C0 = consider.table.C_p_n(consider.table.true_angles_rad(encoder_rad));
    for (int j = 0; j < consider.size(); ++j) {
      const auto& moved = consider.moved_table[static_cast<std::size_t>(j)];
      if (!moved) continue;
      const Eigen::AngleAxisd aa(moved->C_p_n(moved->true_angles_rad(encoder_rad)) * C0.transpose());
      G.col(j) = aa.angle() * aa.axis();
    }
    return G;
  }

  // A restart takes the attitude from the table: its error is then the body alignment's error
  // turned into n, plus the table's reading (C_hat = (I - [phi x]) C, phi = C_b_n delta + G0 p + e,
  // G0 the table's sensitivity to the consider parameters p at the start, e its white error).
  void reset_navigation_covariance(const Matrix3d& C_b_n, const Eigen::Matrix<double, 3, Eigen::Dynamic>& G0) {
    P.topRows(9).setZero();
    P.leftCols(9).setZero();
    const Mat<3, kSize> P_align = P.middleRows(kBodyAlignment.index, kBodyAlignment.size);
    P.middleRows(kAttitude.index, 3) = C_b_n * P_align;
    P.middleCols(kAttitude.index, 3) = P.middleRows(kAttitude.index, 3).transpose();
    P.block<3, 3>(kAttitude.index, kAttitude.index) =
        C_b_n * P_align.middleCols(kBodyAlignment.index, 3) * C_b_n.transpose();
    if (consider.size() > 0) {
      consider.Pxp.topRows(9).setZero();
      const Eigen::Matrix<double, 3, Eigen::Dynamic> Pap = consider.Pxp.middleRows(kBodyAlignment.index, 3);
      // cov(G0 p, x): the navigation rows of Pxp are zero now, so this leaves the attitude block.
      const Mat<3, kSize> from_p = G0 * consider.Pxp.transpose();
      P.middleRows(kAttitude.index, 3) += from_p;
      P.middleCols(kAttitude.index, 3) += from_p.transpose();
      const Matrix3d cross = C_b_n * Pap * G0.transpose();
      P.block<3, 3>(kAttitude.index, kAttitude.index) += cross + cross.transpose() + G0 * G0.transpose();
      consider.Pxp.middleRows(kAttitude.index, 3) = C_b_n * Pap + G0;
    }
    for (int i = 0; i < 9; ++i) P(i, i) += sigma0[i] * sigma0[i];
  }

  void push_temp(const TempSample& temp) {
    if (!thermal_section) return;
    temp_rate.push(temp);
    have_temps = true;
    refresh_compensation();
  }

  // The compensator's coefficients: the filter's current model, at the current temperatures.
  // Until the first temperature sample, the values at T_ref.
  void refresh_compensation() {
    compensated.gyro = model.gyro;
    compensated.accel = model.accel;
    if (thermal_section && have_temps)
      thermal::apply_thermal(*thermal_section, temp_rate.current(), compensated.gyro, compensated.accel);
  }

  void push(const ImuFrame& f) {
    if (stopped) return;
    if (!window.empty()) {
      const double gap_s = static_cast<double>(f.t_ns - window.back().t_ns) * 1e-9;
      if (gap_s > 1.5 * dt_nominal_s || gap_s <= 0) {
        // Never integrate across a gap: restart the navigation after it.
        window.clear();
        nav.reset();
        have_prev_rates = false;
      }
    }
    window.push_back(f);
    const std::size_t needed = comp.window_frames();
    if (window.size() < needed) return;
    step();
    window.pop_front();
  }

  void step() {
    const auto k = static_cast<std::size_t>(comp.lookback());
    t_s = static_cast<double>(window[k].t_ns) * 1e-9;
    if (next_restart < restart_times_s.size() && t_s >= restart_times_s[next_restart]) {
      // A new part of the program: restart the navigation from the table (seed ch. 4).
      while (next_restart < restart_times_s.size() && t_s >= restart_times_s[next_restart]) ++next_restart;
      if (nav) {
        nav.reset();
        ++result.restarts;
        result.restart_times_s.push_back(t_s);
      }
    }
    if (!nav) {
      // The vertical channel runs free here: its velocity and height are measured, which is what
      // makes a scale error common to the three accelerometers (seen only along g) observable.
      const nav::TableReference::Sample start = ref.at(window, k - 1);
      nav = std::make_unique<nav::Strapdown>(ref.initial_state(start), g_mps2, false);
      reset_navigation_covariance(start.C_b_n, table_attitude_sensitivity(window[k - 1]));
      x.head(9).setZero();
      have_prev_rates = false;
    }
    const double dt = static_cast<double>(window[k].t_ns - window[k - 1].t_ns) * 1e-9;
    const nav::CompensatedSample c = comp.compensate(window);
    const nav::TableReference::Sample r = ref.at(window, k);
    nav->update(c.dtheta_rad, c.dv_mps, dt, r.v_n.z(), ref.h_ref_m(r));
    ++result.frames;

    const Vector3d w = c.w_radps;
    // Each accelerometer's errors act on the specific force at its own proof mass (row j).
    const Matrix3d f_channels = c.size_effect_mps2.rowwise() + (c.dv_mps / dt).transpose();
    const Vector3d fb = f_channels.diagonal();
    const Vector3d& wdot = c.dw_radps2;
    const Vector3d fdot = have_prev_rates ? Vector3d((fb - prev_f) / dt) : Vector3d::Zero();
    prev_f = fb;
    have_prev_rates = true;
    const Matrix3d C = nav->state().q_b_n.toRotationMatrix();
    S_C += C * dt;
    S_Cwp += C * w.cwiseMax(0.0).asDiagonal() * dt;
    S_Cwn += C * w.cwiseMin(0.0).asDiagonal() * dt;
    S_Cwdot += C * wdot.asDiagonal() * dt;
    S_Cf += C * fb.asDiagonal() * dt;
    S_Cfdot += C * fdot.asDiagonal() * dt;
    S_fn += table::skew(C * fb) * dt;
    S_CMg += C * gyro_angle_jacobian(w) * dt;
    S_CMa += C * accel_angle_jacobian(f_channels) * dt;
    // Channel j's size effect is row j of ([w x]^2 + [dw x]) r_j: an offset error moves only it.
    const Matrix3d K = table::skew(w) * table::skew(w) + table::skew(c.dw_radps2);
    S_CKy += C.col(1) * K.row(1) * dt;
    S_CKz += C.col(2) * K.row(2) * dt;
    if (!consider.start_terms.empty()) {
      const Vector3d f_o = c.dv_mps / dt, a = fb / units::kStandardGravity_mps2;
      for (int j = 0; j < 3; ++j) {
        const double q = std::abs(w[j]) / kGyroNonlinearityRate_radps;
        for (int m = 0; m < 3; ++m) S_Cq.col(3 * m + j) += C.col(j) * std::pow(q, m + 1) * w[j] * dt;
        for (int i = 0; i < 3; ++i) S_Cfg.col(3 * j + i) += C.col(j) * f_o[i] / units::kStandardGravity_mps2 * dt;
        S_Ca.col(j) += C.col(j) * a[j] * fb[j] * dt;
        S_Ca.col(3 + j) += C.col(j) * a[j] * a[j] * fb[j] * dt;
      }
    }
    S_dt += dt;
    if (S_dt >= opt.propagate_interval_s - 1e-9) {
      propagate();
      since_update_s += S_dt;
      S_dt = 0;
      if (since_update_s >= opt.update_interval_s - 1e-9) {
        since_update_s = 0;
        update(r, window[k]);
      }
    }
  }

  // The covariance over one covariance step: P = Phi P Phi^T (and the consider parameters'
  // cross terms), the process noise, then the step's sums cleared for the next.
  //
  // Only the navigation error moves: F's rows below the first kNav are zero (the coefficients are
  // constants, their drift is process noise), so Phi = [[A, B], [0, I]] and only P's first kNav
  // rows and columns change. Computed so, a step costs kNav N^2 instead of 3 N^3 (a tenth of the
  // filter's time at 100 Hz before); the result is Phi P Phi^T to rounding.
  void propagate() {
    const double T = S_dt;
    const StateMatrix Fdt = transition_dt(T);
    const NavRows F_top = Fdt.topRows<kNav>();
    NavRows Phi_top = F_top + 0.5 * F_top.leftCols<kNav>() * F_top;  // (F + F^2 / 2)'s rows: F^2 = F_nav F
    Phi_top.leftCols<kNav>() += Eigen::Matrix<double, kNav, kNav>::Identity();
    const NavRows PhiP_top = Phi_top * P;  // the rest of Phi P is P's own rows
    const Eigen::Matrix<double, kNav, kNav> nav_nav = PhiP_top * Phi_top.transpose();
    P.topRows<kNav>() = PhiP_top;
    P.topLeftCorner<kNav, kNav>() = nav_nav;
    P.bottomLeftCorner<state::kSize - kNav, kNav>() = PhiP_top.rightCols<state::kSize - kNav>().transpose();
    if (consider.size() > 0) propagate_consider(Phi_top, T);
    add_process_noise(T);
    ++result.covariance_steps;
    clear_step_sums();
  }

  // F T over the step, from the navigation state and the step's sums of the sensor terms.
  StateMatrix transition_dt(double T) const {
    const nav::NavState& s = nav->state();
    const double lat = s.lat_rad, R = ref.RM_m(), Omega = earth::kOmega_radps;
    const Vector3d w_ie = earth::w_ie_n(lat);
    const Vector3d w_en(-s.v_n.y() / R, s.v_n.x() / R, s.v_n.x() * std::tan(lat) / R);
    StateMatrix Fdt = StateMatrix::Zero();
    auto blk = [&](const Block& r, const Block& c) { return Fdt.block(r.index, c.index, r.size, c.size); };
    blk(kAttitude, kAttitude) = -table::skew(w_ie + w_en) * T;
    Fdt(0, 4) = -T / R;                   // phi_E from dv_N
    Fdt(1, 3) = T / R;                    // phi_N from dv_E
    Fdt(2, 3) = std::tan(lat) * T / R;    // phi_U from dv_E
    Fdt(1, 7) = -Omega * std::sin(lat) * T / R;  // Earth rate seen at the wrong latitude
    Fdt(2, 7) = Omega * std::cos(lat) * T / R;
    blk(kAttitude, kGyroBias) = -S_C;
    blk(kAttitude, kGyroScalePos) = -S_Cwp;
    blk(kAttitude, kGyroScaleNeg) = -S_Cwn;
    blk(kAttitude, kGyroAngles) = -S_CMg;
    blk(kAttitude, kGyroDelay) = S_Cwdot;
    blk(kVelocity, kAttitude) = S_fn;
    blk(kVelocity, kVelocity) = -table::skew(2.0 * w_ie + w_en) * T;
    blk(kVelocity, kAccelBias) = S_C;
    blk(kVelocity, kAccelScale) = S_Cf;
    blk(kVelocity, kAccelAngles) = S_CMa;
    blk(kVelocity, kAccelDelay) = -S_Cfdot;
    blk(kVelocity, kLeverArmY) = S_CKy;
    blk(kVelocity, kLeverArmZ) = S_CKz;
    blk(kPosition, kVelocity) = Matrix3d::Identity() * T;
    return Fdt;
  }

  // x' = Phi x + Gamma p: the consider parameters' part of the step (Schmidt). A consider
  // parameter moves the navigation error only (Gamma's rows below kNav are zero), so the products
  // are kept to those rows: kNav N c instead of N^2 c (c the parameters; with a table's errors
  // considered the dense products were a seventh of stage 3's time).
  void propagate_consider(const NavRows& Phi_top, double T) {
    Eigen::Matrix<double, kNav, Eigen::Dynamic> Gamma = Eigen::Matrix<double, kNav, Eigen::Dynamic>::Zero(kNav, consider.size());
    // The site's g, if wrong by its sigma, accelerates the vertical channel.
    if (consider.gravity >= 0) Gamma(kVelocity.index + 2, consider.gravity) = consider.gravity_sigma_mps2 * T;
    // A start term wrong by its sigma: the gyro's rate error turns the attitude (-C dw, as a
    // bias does), the accelerometer's force error the velocity (C df).
    using Term = Consider::StartTerm;
    for (const Term& t : consider.start_terms) {
      auto att = Gamma.block<3, 1>(kAttitude.index, t.column);
      auto vel = Gamma.block<3, 1>(kVelocity.index, t.column);
      switch (t.kind) {
        case Term::kGyroScaleNonlinear: att = -S_Cq.col(3 * t.k + t.j) * t.sigma; break;
        case Term::kGyroGSensitivity: att = -S_Cfg.col(3 * t.j + t.k) * t.sigma; break;
        case Term::kAccelK2: vel = S_Ca.col(t.j) * t.sigma; break;
        case Term::kAccelK3: vel = S_Ca.col(3 + t.j) * t.sigma; break;
      }
    }
    ConsiderMatrix PhiPxp = consider.Pxp;  // Phi's rows below kNav are the identity's
    PhiPxp.topRows<kNav>() = Phi_top * consider.Pxp;
    // P += cross + cross^T + Gamma Gamma^T, each nonzero in P's first kNav columns or rows only.
    const Eigen::Matrix<double, kSize, kNav> cross = PhiPxp * Gamma.transpose();
    P.leftCols<kNav>() += cross;
    P.topRows<kNav>() += cross.transpose();
    P.topLeftCorner<kNav, kNav>() += Gamma * Gamma.transpose();
    consider.Pxp = PhiPxp;
    consider.Pxp.topRows<kNav>() += Gamma;
  }

  void add_process_noise(double T) {
    StateVector q = StateVector::Zero();
    const double arw = model.gyro.noise.arw_rad_rts, vrw = model.accel.noise.vrw_mps_rts;
    const double qbg = opt.gyro_bias_rw_radps_rts > 0 ? opt.gyro_bias_rw_radps_rts
                                                      : model.gyro.noise.rate_random_walk_radps_rts;
    const double qba = opt.accel_bias_rw_mps2_rts > 0 ? opt.accel_bias_rw_mps2_rts
                                                      : model.accel.noise.accel_random_walk_mps2_rts;
    seg(q, kAttitude).setConstant(arw * arw * T);
    seg(q, kVelocity).setConstant(vrw * vrw * T);
    seg(q, kGyroBias).setConstant(qbg * qbg * T);
    seg(q, kAccelBias).setConstant(qba * qba * T);
    for (const Block& b : {kGyroScalePos, kGyroScaleNeg, kAccelScale}) seg(q, b).setConstant(opt.scale_rw_rts * opt.scale_rw_rts * T);
    P.diagonal() += q;
    P = 0.5 * (P + P.transpose());
  }

  void clear_step_sums() {
    S_C.setZero();
    S_Cwp.setZero();
    S_Cwn.setZero();
    S_Cwdot.setZero();
    S_Cf.setZero();
    S_Cfdot.setZero();
    S_fn.setZero();
    S_CMa.setZero();
    S_CMg.setZero();
    S_CKy.setZero();
    S_CKz.setZero();
    S_Cq.setZero();
    S_Cfg.setZero();
    S_Ca.setZero();
  }

  // One scalar measurement z = H x + G p + noise (variance R), p the consider parameters (G empty:
  // none), gated. The covariance in the Joseph form (I - K H) P (I - K H)^T + K R K^T (with the
  // Schmidt filter's terms of p), written out as rank-one corrections: the same algebra, O(n^2)
  // instead of three n^3 products per scalar (which were most of stage 3's time).
  bool scalar_update(const StateVector& H, const Eigen::VectorXd& G, double z, double R, MeasurementRecord& rec,
                     std::size_t m) {
    const StateVector PxpG = consider.size() > 0 && G.size() > 0 ? StateVector(consider.Pxp * G) : StateVector::Zero();
    const double GG = G.size() > 0 ? G.squaredNorm() : 0.0;
    const StateVector PH = P * H + PxpG;  // cov(x, z)
    const double innovation = z - H.dot(x), S = H.dot(PH) + H.dot(PxpG) + GG + R;
    const double ratio = innovation * innovation / (opt.gate_sigma * opt.gate_sigma * S);
    rec.innovation[m] = innovation;
    rec.variance[m] = S;
    rec.test_ratio[m] = ratio;
    rec.accepted[m] = ratio <= 1.0;
    if (!rec.accepted[m]) {
      ++result.rejected;
      return false;
    }
    const StateVector K = PH / S;
    x += K * innovation;
    // x+ - x_true = (I - K H) e + K (G p + noise): P - K PH^T - PH K^T + S K K^T, for any gain K.
    P.noalias() -= K * PH.transpose();
    P.noalias() -= PH * K.transpose();
    P.noalias() += (S * K) * K.transpose();
    P = 0.5 * (P + P.transpose());
    if (consider.size() > 0) {
      // cov(x+ - x_true, p) = (I - K H) Pxp - K G^T.
      Eigen::RowVectorXd HPxp = H.transpose() * consider.Pxp;
      if (G.size() > 0) HPxp += G.transpose();
      consider.Pxp.noalias() -= K * HPxp;
    }
    return true;
  }

  void update(const nav::TableReference::Sample& r, const ImuFrame& frame) {
    const nav::NavState& s = nav->state();
    const Vector3d dv = s.v_n - r.v_n, dp = ref.position_error_m(s, r);
    const std::array<double, 6> z = {dv.x(), dv.y(), dv.z(), dp.x(), dp.y(), dp.z()};
    MeasurementRecord rec{t_s, {}, {}, {}, {}};
    int accepted = 0;
    for (std::size_t m = 0; m < 6; ++m) {
      StateVector H = StateVector::Zero();
      H[kVelocity.index + static_cast<int>(m)] = 1.0;  // velocity and position blocks are adjacent
      const double R = m < 3 ? opt.velocity_noise_mps * opt.velocity_noise_mps : opt.position_noise_m * opt.position_noise_m;
      accepted += scalar_update(H, Eigen::VectorXd(), z[m], R, rec, m);
    }
    if (opt.attitude_noise_rad > 0) {
      // The table's attitude: C_ref C_hat^T = I + [(phi - C_b_n delta) x], delta the error of the
      // body frame's alignment on the platform (at a restart the navigation takes it over).
      // The table's own errors p turn its reading by G p (consider): z = phi - C_b_n delta - G p.
      const Eigen::AngleAxisd aa(r.C_b_n * s.q_b_n.toRotationMatrix().transpose());
      const Vector3d z_att = aa.angle() * aa.axis();
      const Eigen::Matrix<double, 3, Eigen::Dynamic> G = table_attitude_sensitivity(frame);
      for (int m = 0; m < 3; ++m) {
        StateVector H = StateVector::Zero();
        H[kAttitude.index + m] = 1.0;
        seg(H, kBodyAlignment) = -r.C_b_n.row(m).transpose();
        accepted += scalar_update(H, -G.row(m).transpose(), z_att[m], opt.attitude_noise_rad * opt.attitude_noise_rad,
                                  rec, static_cast<std::size_t>(6 + m));
      }
    }
    result.measurements.push_back(rec);
    ++result.updates;
    consecutive_rejections = accepted == 0 ? consecutive_rejections + 1 : 0;
    char buf[240];
    if (consecutive_rejections >= opt.divergence_rejections) {
      std::snprintf(buf, sizeof buf,
                    "diverged at t=%.1f s: %d updates in a row had every innovation outside the %.0f-sigma gate",
                    t_s, consecutive_rejections, opt.gate_sigma);
      fail(buf);
      return;
    }
    for (int i = 0; i < kSize; ++i)
      if (!(P(i, i) >= 0.0) || !std::isfinite(P(i, i))) {
        std::snprintf(buf, sizeof buf, "covariance lost positiveness at t=%.1f s (state %d)", t_s, i);
        fail(buf);
        return;
      }
    feedback();
    // A delay moved beyond what the compensation window follows: the filter has run away (the
    // window is sized for +-max_delay_s, docs/stage3.md); compensating would read past its frames.
    if (const std::string delay = comp.unfollowed_delay(); !delay.empty()) {
      std::snprintf(buf, sizeof buf, "diverged at t=%.1f s: the %s estimate left the +-%.3g s the compensation follows",
                    t_s, delay.c_str(), opt.max_delay_s);
      fail(buf);
      return;
    }
    const StateVector now = model_to_state(model), start = model_to_state(model_at_start);
    for (int i = 0; i < 6; ++i)
      if (std::abs(now[kGyroAngles.index + i] - start[kGyroAngles.index + i]) > 60.0 * units::kArcsecToRad ||
          (i < 3 && std::abs(now[kAccelAngles.index + i] - start[kAccelAngles.index + i]) > 60.0 * units::kArcsecToRad)) {
        std::snprintf(buf, sizeof buf,
                      "stage-1 errors too large for the linear filter: an axis angle moved by more than 1' by t=%.1f s "
                      "(run stage direct first)",
                      t_s);
        fail(buf);
        return;
      }
    if (t_s >= next_history_s) {
      record_history();
      next_history_s = t_s + opt.history_interval_s;
    }
  }

  void feedback() {
    // Navigation: C_true = (I + [phi x]) C_hat, v_true = v_hat - dv, p_true = p_hat - dp.
    nav::NavState& s = nav->mutable_state();
    s.q_b_n = (nav::quat_from_rotvec(seg(x, kAttitude)) * s.q_b_n).normalized();
    s.v_n -= seg(x, kVelocity);
    s.h_m -= x[kPosition.index + 2];
    s.lat_rad -= x[kPosition.index + 1] / ref.RM_m();
    s.lon_rad -= x[kPosition.index] / (ref.RN_m() * std::cos(ref.latitude_rad()));
    // Model: every residual is "true minus model", so the model moves by the estimate.
    model.gyro.bias_radps += seg(x, kGyroBias);
    model.accel.bias_mps2 += seg(x, kAccelBias);
    model.gyro.scale_pos += seg(x, kGyroScalePos);
    model.gyro.scale_neg += seg(x, kGyroScaleNeg);
    model.accel.scale += seg(x, kAccelScale);
    for (std::size_t i = 0; i < 6; ++i)
      model.gyro.misalignment_rad.*kGyroAngleKeys[i] += x[kGyroAngles.index + static_cast<int>(i)];
    for (std::size_t i = 0; i < 3; ++i)
      model.accel.misalignment_rad.*kAccelAngleKeys[i] += x[kAccelAngles.index + static_cast<int>(i)];
    model.gyro.delay_s += seg(x, kGyroDelay);
    model.accel.delay_s += seg(x, kAccelDelay);
    // The filter sees the offsets in its (body) frame; the model keeps them in o: v_o = C_b_o v_b.
    const Matrix3d C_b_o = C_b_o_of(model.body_to_instrument_rad.value_or(Vector3d::Zero()));
    model.accel.lever_arm_y_m += C_b_o * seg(x, kLeverArmY);
    model.accel.lever_arm_z_m += C_b_o * seg(x, kLeverArmZ);
    model.body_to_instrument_rad = model.body_to_instrument_rad.value_or(Vector3d::Zero()) + seg(x, kBodyAlignment);
    ref.set_body_to_instrument(*model.body_to_instrument_rad);
    x.setZero();
    refresh_compensation();
  }

  void record_history() {
    HistoryRecord h{t_s, model_to_state(model), P.diagonal().cwiseMax(0.0).cwiseSqrt()};
    result.history.push_back(h);
  }

  void fail(const std::string& why) {
    result.converged = false;
    result.status = "not converged: " + why;
    stopped = true;
  }

  // The model with the sigma of the calibration states (the others as the input model had them).
  ImuModel model_with_sigma(const StateVector& sd) const {
    ImuModel m = model;
    m.sigma = with_calibration_states(sd, model.sigma.value_or(ImuErrorSet{}));
    return m;
  }

  // `set` with the fields of the calibration states replaced by `sd`'s (model units, SI).
  static ImuErrorSet with_calibration_states(const StateVector& sd, ImuErrorSet sg) {
    sg.gyro.bias_radps = seg(sd, kGyroBias);
    sg.accel.bias_mps2 = seg(sd, kAccelBias);
    sg.gyro.scale_pos = seg(sd, kGyroScalePos);
    sg.gyro.scale_neg = seg(sd, kGyroScaleNeg);
    sg.accel.scale = seg(sd, kAccelScale);
    for (std::size_t i = 0; i < 6; ++i) sg.gyro.misalignment_rad.*kGyroAngleKeys[i] = sd[kGyroAngles.index + static_cast<int>(i)];
    sg.accel.misalignment_rad = {};
    for (std::size_t i = 0; i < 3; ++i) sg.accel.misalignment_rad.*kAccelAngleKeys[i] = sd[kAccelAngles.index + static_cast<int>(i)];
    sg.gyro.delay_s = seg(sd, kGyroDelay);
    sg.accel.delay_s = seg(sd, kAccelDelay);
    sg.accel.lever_arm_y_m = seg(sd, kLeverArmY);
    sg.accel.lever_arm_z_m = seg(sd, kLeverArmZ);
    return sg;
  }

  // The budget of the calibration states (ImuModel::budget): the filter's own (type_a: the noise
  // and the start's uncertainty) and each consider source's share, Pxp's row squared over the
  // source's parameters; the start model's budget carried for the coefficients this stage leaves.
  std::map<std::string, ImuErrorSet> budget() const {
    std::map<std::string, ImuErrorSet> out;
    for (const auto& [source, set] : model.budget) out[source] = with_calibration_states(StateVector::Zero(), set);
    std::map<std::string, StateVector> variance;
    StateVector type_b = StateVector::Zero();
    for (int j = 0; j < consider.size(); ++j) {
      const StateVector v = consider.Pxp.col(j).cwiseAbs2();
      variance.try_emplace(consider.source[static_cast<std::size_t>(j)], StateVector::Zero()).first->second += v;
      type_b += v;
    }
    out["type_a"] = with_calibration_states((P.diagonal() - type_b).cwiseMax(0.0).cwiseSqrt(), out["type_a"]);
    for (const auto& [source, v] : variance)
      out[source] = with_calibration_states(v.cwiseSqrt(), out[source]);
    return out;
  }

  Progress progress() const {
    Progress p;
    const StateVector sd = P.diagonal().cwiseMax(0.0).cwiseSqrt();
    p.model = model_with_sigma(sd);
    p.t_s = t_s;
    p.frames = result.frames;
    p.updates = result.updates;
    p.rejected = result.rejected;
    p.restarts = result.restarts;
    p.restart_times_s = result.restart_times_s;
    if (!result.measurements.empty()) p.last_measurement = result.measurements.back();
    p.gate_sigma = opt.gate_sigma;
    p.sigma0 = sigma0;
    p.sigma = sd;
    if (!result.converged) {
      p.status = result.status;
    } else if (consecutive_rejections > 0) {
      p.status = "rejecting: " + std::to_string(consecutive_rejections) + " update(s) in a row with every innovation outside the " +
                 std::to_string(static_cast<int>(opt.gate_sigma)) + "-sigma gate (diverged at " +
                 std::to_string(opt.divergence_rejections) + ")";
    } else {
      p.status = "running";
    }
    return p;
  }

  Result finish() {
    Result r = std::move(result);
    if (r.converged) r.status = "converged";
    if (r.updates == 0 && r.converged) {
      r.converged = false;
      r.status = "not converged: no measurement update (the recording is too short)";
    }
    r.sigma_final = P.diagonal().cwiseMax(0.0).cwiseSqrt();
    r.P_calibration = P.block<kCalibrationSize, kCalibrationSize>(kFirstCalibration, kFirstCalibration);
    r.model_values = model_to_state(model);
    const int gx = kGyroDelay.index;
    r.tau_yx_s = model.gyro.delay_s[1] - model.gyro.delay_s[0];
    r.tau_zx_s = model.gyro.delay_s[2] - model.gyro.delay_s[0];
    r.sigma_tau_yx_s = std::sqrt(std::max(0.0, P(gx + 1, gx + 1) + P(gx, gx) - 2 * P(gx, gx + 1)));
    r.sigma_tau_zx_s = std::sqrt(std::max(0.0, P(gx + 2, gx + 2) + P(gx, gx) - 2 * P(gx, gx + 2)));
    r.model = model_with_sigma(r.sigma_final);
    r.model.budget = budget();
    nlohmann::json extra = r.model.extra_json.empty() ? nlohmann::json::object() : nlohmann::json::parse(r.model.extra_json);
    extra["status"] = r.status;
    r.model.extra_json = extra.dump();
    return r;
  }
};

NavCalibrationFilter::NavCalibrationFilter(const RecordingMeta& meta, const ImuModel& model, const Options& options)
    : impl_(std::make_unique<Impl>(meta, model, options)) {}
NavCalibrationFilter::~NavCalibrationFilter() = default;
void NavCalibrationFilter::push(const ImuFrame& frame) { impl_->push(frame); }
void NavCalibrationFilter::push_temp(const TempSample& temp) { impl_->push_temp(temp); }
Progress NavCalibrationFilter::progress() const { return impl_->progress(); }
Result NavCalibrationFilter::finish() { return impl_->finish(); }

std::string Result::history_json() const {
  nlohmann::json j;
  std::vector<double> t;
  for (const auto& h : history) t.push_back(h.t_s);
  j["t_s"] = t;
  for (const Block& b : kAll) {
    if (b.index < kFirstCalibration) continue;
    for (int i = 0; i < b.size; ++i) {
      std::vector<double> v, s;
      for (const auto& h : history) {
        v.push_back(h.value[b.index + i]);
        s.push_back(h.sigma[b.index + i]);
      }
      const std::string key = std::string(b.name) + "[" + std::to_string(i) + "]";
      j["value"][key] = v;
      j["sigma"][key] = s;
    }
  }
  nlohmann::json m = nlohmann::json::array();
  for (const auto& r : measurements)
    m.push_back({r.t_s, r.innovation, r.variance, r.test_ratio, r.accepted});
  j["measurements"] = {{"columns", {"t_s", "innovation", "variance", "test_ratio", "accepted"}}, {"rows", m}};
  return j.dump();
}

}  // namespace imucal::navfilter
