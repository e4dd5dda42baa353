/* terminal_descent.c: a small flight software in plain C for the oils bench.
 *
 * Flies the terminal-descent scenario (emulator/config/scenarios/terminal-descent.toml:
 * 2 km up, slow, over the site) to a soft touchdown. Vertical channel: a descent-speed
 * profile v_ref(h) tracked by a proportional loop on top of gravity. Horizontal: velocity
 * nulling by tilting the thrust. Attitude: the four engines throttle together and the
 * attitude thrusters point body +Z along the demanded thrust (PD).
 *
 * Build:  cc -std=c11 -O2 -shared -fPIC -I shared/include \
 *            onboard-stub/examples/c/terminal_descent.c -o libterminal_descent.so -lm
 * Fly:    oils run --scenario emulator/config/scenarios/terminal-descent.toml \
 *            --fsw c:./libterminal_descent.so
 * Optional parameters (--fsw-params FILE), one `name = value` per line:
 *            max_descent_speed_m_s, touchdown_speed_m_s, decel_m_s2. */
#include "oils.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MOON_MU_M3_S2 4.9028e12
#define MOON_ROTATION_RAD_S 2.6617e-6 /* sidereal: 2 pi / 27.321661 d */
#define ENGINE_MIN_N 320.0   /* 40 % of 800 N */
#define ENGINE_MAX_N 800.0
#define INERTIA_KG_M2 1000.0 /* rough, every axis */
#define DEG_TO_RAD (3.14159265358979323846 / 180.0)

typedef struct {
  double max_descent_speed_m_s;
  double touchdown_speed_m_s;
  double decel_m_s2;
} fsw_ctx;

uint32_t oils_fsw_abi_version(void) { return OILS_FSW_ABI_VERSION; }
uint64_t oils_fsw_layout_hash(void) { return OILS_FSW_LAYOUT_HASH; }

void *oils_fsw_init(const oils_fsw_config *config) {
  fsw_ctx *ctx = malloc(sizeof *ctx);
  if (ctx == NULL) return NULL;
  ctx->max_descent_speed_m_s = 20.0;
  ctx->touchdown_speed_m_s = 1.0;
  ctx->decel_m_s2 = 0.6;
  /* Parameters: `name = value` lines; anything else refuses the run. */
  const char *p = config->params;
  while (p != NULL && *p != '\0') {
    char name[64];
    double value;
    if (sscanf(p, " %63[a-z_0-9] = %lf", name, &value) == 2) {
      if (strcmp(name, "max_descent_speed_m_s") == 0) ctx->max_descent_speed_m_s = value;
      else if (strcmp(name, "touchdown_speed_m_s") == 0) ctx->touchdown_speed_m_s = value;
      else if (strcmp(name, "decel_m_s2") == 0) ctx->decel_m_s2 = value;
      else { free(ctx); return NULL; }
    }
    p = strchr(p, '\n');
    if (p != NULL) p++;
  }
  return ctx;
}

void oils_fsw_fini(void *ctx) { free(ctx); }

static double dot(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* v_out = R(q) v for q = [w, x, y, z] (sign = +1), or R(q)^T v (sign = -1). */
static void rotate(const double q[4], int sign, const double v[3], double out[3]) {
  const double w = q[0], x = sign * q[1], y = sign * q[2], z = sign * q[3];
  const double t[3] = {2.0 * (y * v[2] - z * v[1]), 2.0 * (z * v[0] - x * v[2]),
                       2.0 * (x * v[1] - y * v[0])};
  out[0] = v[0] + w * t[0] + (y * t[2] - z * t[1]);
  out[1] = v[1] + w * t[1] + (z * t[0] - x * t[2]);
  out[2] = v[2] + w * t[2] + (x * t[1] - y * t[0]);
}

int32_t oils_fsw_step(void *context, const oils_telemetry *tlm, oils_command *cmd) {
  const fsw_ctx *ctx = context;
  const oils_nav_state *nav = &tlm->nav;
  const double r = sqrt(dot(nav->pos_mci_m, nav->pos_mci_m));
  if (!(r > 0.0) || !(tlm->mass_estimate_kg > 0.0)) return 1; /* nonsense telemetry */
  const double up[3] = {nav->pos_mci_m[0] / r, nav->pos_mci_m[1] / r, nav->pos_mci_m[2] / r};
  const double g = MOON_MU_M3_S2 / (r * r);

  /* On the legs: engines off, no torque; the vehicle settles under its weight. */
  if (tlm->header.flags & OILS_TLM_FLAG_FOOTPAD_CONTACT) {
    memset(cmd->thrust_cmd_n, 0, sizeof cmd->thrust_cmd_n);
    memset(cmd->engine_on, 0, sizeof cmd->engine_on);
    memset(cmd->torque_cmd_body_nm, 0, sizeof cmd->torque_cmd_body_nm);
    return 0;
  }

  /* Velocity relative to the turning ground: v - omega x r, omega along mci +Z. */
  const double v_rel[3] = {nav->vel_mci_m_s[0] + MOON_ROTATION_RAD_S * nav->pos_mci_m[1],
                           nav->vel_mci_m_s[1] - MOON_ROTATION_RAD_S * nav->pos_mci_m[0],
                           nav->vel_mci_m_s[2]};

  /* Vertical: follow a descent-speed profile that brakes to touchdown speed. */
  const double h = fmax(tlm->altitude_m, 0.0);
  double v_ref = fmin(ctx->max_descent_speed_m_s, sqrt(2.0 * ctx->decel_m_s2 * h));
  v_ref = -fmax(v_ref, ctx->touchdown_speed_m_s);
  const double v_up = dot(v_rel, up);
  const double a_up = g + 1.0 * (v_ref - v_up);

  /* Horizontal: null the velocity, tilting at most 10 degrees (3 near the ground). */
  double a[3];
  const double max_tilt = tan((h > 20.0 ? 10.0 : 3.0) * DEG_TO_RAD);
  double a_h[3], a_h_norm = 0.0;
  for (int i = 0; i < 3; i++) {
    a_h[i] = -0.3 * (v_rel[i] - v_up * up[i]);
    a_h_norm += a_h[i] * a_h[i];
  }
  a_h_norm = sqrt(a_h_norm);
  const double a_h_max = max_tilt * fmax(a_up, 0.1);
  const double scale = a_h_norm > a_h_max ? a_h_max / a_h_norm : 1.0;
  for (int i = 0; i < 3; i++) a[i] = a_up * up[i] + scale * a_h[i];
  const double a_norm = sqrt(dot(a, a));

  /* Thrust: shared equally by the four engines, within the throttle range. */
  double per_engine = tlm->mass_estimate_kg * a_norm / OILS_ENGINE_COUNT;
  per_engine = fmin(fmax(per_engine, ENGINE_MIN_N), ENGINE_MAX_N);
  for (int i = 0; i < OILS_ENGINE_COUNT; i++) {
    cmd->thrust_cmd_n[i] = per_engine;
    cmd->engine_on[i] = 1;
  }

  /* Attitude: turn body +Z towards the demanded acceleration. */
  const double z_body[3] = {0.0, 0.0, 1.0};
  double z_mci[3], err_mci[3], err_body[3];
  rotate(nav->q_mci_from_body, +1, z_body, z_mci);
  const double d[3] = {a[0] / a_norm, a[1] / a_norm, a[2] / a_norm};
  err_mci[0] = z_mci[1] * d[2] - z_mci[2] * d[1];
  err_mci[1] = z_mci[2] * d[0] - z_mci[0] * d[2];
  err_mci[2] = z_mci[0] * d[1] - z_mci[1] * d[0];
  rotate(nav->q_mci_from_body, -1, err_mci, err_body);
  for (int i = 0; i < 3; i++) {
    /* Natural frequency 1 rad/s, damping 0.8. */
    cmd->torque_cmd_body_nm[i] =
        INERTIA_KG_M2 * (1.0 * err_body[i] - 1.6 * nav->rate_body_rad_s[i]);
  }
  return OILS_FSW_STATUS_OK;
}
