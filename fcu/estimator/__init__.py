"""Error-state (multiplicative) EKF: IMU-driven strapdown fusing a delayed external pose.

Frames and units: world ENU (g_W = [0, 0, -g]), body FLU, Hamilton quaternions (w, x, y, z),
q_enu_flu body to world, time in integer microseconds. The accelerometer measures the
specific force f = R^T (a_W - g_W) + b_a + n, the gyro omega + b_g + n.

Nominal state x = (p, v, q, b_g, b_a); error state dx = [dp, dv, dtheta, db_g, db_a] with the
local (body) attitude error q = q_hat * exp(dtheta) (Sola, "Quaternion kinematics for the
error-state Kalman filter", 2017, sec. 5.3 and 7). The pose is plain quaternion + vector
(not a dual quaternion): position and attitude are gated and fused as separate 3-vectors.

- Strapdown (Sola sec. 5.4.1, eq. 260; each sample held over the interval ending at its t_us,
  the specific force rotated to mid-interval): p += v dt + a_W dt^2/2, v += a_W dt,
  q = q exp((w_m - b_g) dt).
- Covariance (Sola sec. 5.4.3, eq. 269-274): P = F P F^T + Q with F = I + [dp/dv = I dt,
  dv/dtheta = -R [a]x dt, dv/db_a = -R dt, dtheta/dtheta = I - [w dt]x, dtheta/db_g = -I dt].
  Discretisation: per IMU sample, delta-velocity variance (accel_noise dt)^2 and delta-angle
  variance (gyro_noise dt)^2 (Sola eq. 271-272, EKF2's daxVar/dvxVar: the settings are the
  per-sample sigmas); bias random walks sigma^2 dt (Sola eq. 273-274: densities).
- Update: Joseph form, symmetrised, diagonal floors; injection and reset Jacobian
  G = I - [dtheta/2]x on the attitude block (Sola sec. 6.2-6.3, eq. 282-287).
- Covariance steps every cov_period_s of IMU time (EKF2_PREDICT_US) from the interval's
  deltas, and before every fusion; the nominal state integrates every sample.
- Delayed fusion as EKF2 (EKF2_EV_DELAY): the filter runs at the horizon
  t_h = newest IMU - pose_delay_s on the buffered IMU samples; a pose is fused at the
  buffered sample nearest its capture time. Output predictor: the output state integrates
  each new sample once; a horizon correction is carried to it by the linearised transition
  over the buffered interval (no lag, no EKF2-style feedback time constant), and every
  output_resync_s (and after resets) the buffered samples are re-propagated exactly. Both
  agree within 1 um; re-propagating after every fusion costs ~2x (bench_estimator.py).
- Gates (EKF2 test ratio): max over axes of innov^2 / (gate^2 S) > 1 refuses position or
  attitude (separately). A pose counts as fused when both parts pass, else as rejected (a
  passing part is still fused). After pose_reset_timeout_s of refused position (attitude),
  the position (attitude) resets to the pose, as EKF2 resets to vision after
  reset_timeout_max.

The parts: `settings`, `inputs` and `status` (what goes in and out), `strapdown`
(the nominal step and its transition), `align` (the stationary window), `update` (the
measurement update), `output` (the output predictor) and `ekf` (the filter, `Estimator`).
"""
