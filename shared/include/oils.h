/* oils.h: the oils bench's wire packets and flight-software C ABI, v1.
 *
 * GENERATED from shared/src/lib.rs (SCHEMA) and shared/src/c_abi.rs; do not edit.
 * Regenerate: cargo run -p oils-shared --example c_header > shared/include/oils.h
 * Meaning of every field, units and frames: docs/protocol.md. Build your flight
 * software as a shared library exporting the five oils_fsw_* functions below and fly
 * it with `oils run --fsw c:PATH/libmyfsw.so` (or `oils stub --fsw c:PATH`).
 * Targets: 64-bit little-endian; the _Static_asserts below check sizes and offsets. */
#ifndef OILS_H
#define OILS_H

#include <stdint.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define OILS_PROTOCOL_VERSION 1u
#define OILS_SCHEMA_HASH UINT64_C(0xa8f0da5f8f0aee6e)
#define OILS_FSW_ABI_VERSION 1u
#define OILS_FSW_LAYOUT_HASH UINT64_C(0x0275de28a2a3628b)
#define OILS_ENGINE_COUNT 4
#define OILS_TLM_FLAG_END_OF_RUN 1u /* last telemetry: answer nothing */
#define OILS_TLM_FLAG_NAV_NOISE 2u  /* nav values carry seeded noise */
#define OILS_TLM_FLAG_FOOTPAD_CONTACT 4u  /* a footpad touches the ground: engines off */
#define OILS_FSW_STATUS_OK 0 /* any other value from oils_fsw_step stops the run */

/* The schema string whose FNV-1a 64 hash is OILS_SCHEMA_HASH. */
#define OILS_SCHEMA \
  "PacketHeader{protocol_version:u32@0,flags:u32@4,schema_hash:u64@8,run_id:u64@16,step:u64@24,t_ns:i64@32}=40|" \
  "NavState{pos_mci_m:[f64;3]@0,vel_mci_m_s:[f64;3]@24,q_mci_from_body:[f64;4]@48,rate_body_rad_s:[f64;3]@80}=104|" \
  "EngineReading{thrust_n:f64@0,chamber_pressure_pa:f64@8,valve_open:u32@16,flags:u32@20}=24|" \
  "PropulsionReadings{gas_pressure_pa:f64@0,fuel_tank_pressure_pa:f64@8,ox_tank_pressure_pa:f64@16,engines:[EngineReading;4]@24}=120|" \
  "Telemetry{header:PacketHeader@0,nav:NavState@40,accel_body_m_s2:[f64;3]@144,altitude_m:f64@168,mass_estimate_kg:f64@176,propulsion:PropulsionReadings@184}=304|" \
  "Command{header:PacketHeader@0,thrust_cmd_n:[f64;4]@40,engine_on:[u32;4]@72,torque_cmd_body_nm:[f64;3]@88,stub_compute_ns:u64@112}=120|"

typedef struct oils_packet_header {
  uint32_t protocol_version;
  uint32_t flags;
  uint64_t schema_hash;
  uint64_t run_id;
  uint64_t step;
  int64_t t_ns;
} oils_packet_header;

typedef struct oils_nav_state {
  double pos_mci_m[3];
  double vel_mci_m_s[3];
  double q_mci_from_body[4];
  double rate_body_rad_s[3];
} oils_nav_state;

typedef struct oils_engine_reading {
  double thrust_n;
  double chamber_pressure_pa;
  uint32_t valve_open;
  uint32_t flags;
} oils_engine_reading;

typedef struct oils_propulsion_readings {
  double gas_pressure_pa;
  double fuel_tank_pressure_pa;
  double ox_tank_pressure_pa;
  oils_engine_reading engines[4];
} oils_propulsion_readings;

typedef struct oils_telemetry {
  oils_packet_header header;
  oils_nav_state nav;
  double accel_body_m_s2[3];
  double altitude_m;
  double mass_estimate_kg;
  oils_propulsion_readings propulsion;
} oils_telemetry;

typedef struct oils_command {
  oils_packet_header header;
  double thrust_cmd_n[4];
  uint32_t engine_on[4];
  double torque_cmd_body_nm[3];
  uint64_t stub_compute_ns;
} oils_command;

typedef struct oils_fsw_config {
  uint32_t abi_version;
  uint32_t protocol_version;
  uint64_t schema_hash;
  uint64_t run_id;
  const char *params;
  uint64_t params_len;
} oils_fsw_config;

#ifdef __cplusplus
#define OILS_STATIC_ASSERT(c, m) static_assert(c, m)
#else
#define OILS_STATIC_ASSERT(c, m) _Static_assert(c, m)
#endif
OILS_STATIC_ASSERT(sizeof(double) == 8 && sizeof(void *) == 8, "64-bit target");
OILS_STATIC_ASSERT(offsetof(oils_packet_header, protocol_version) == 0, "oils_packet_header.protocol_version offset");
OILS_STATIC_ASSERT(offsetof(oils_packet_header, flags) == 4, "oils_packet_header.flags offset");
OILS_STATIC_ASSERT(offsetof(oils_packet_header, schema_hash) == 8, "oils_packet_header.schema_hash offset");
OILS_STATIC_ASSERT(offsetof(oils_packet_header, run_id) == 16, "oils_packet_header.run_id offset");
OILS_STATIC_ASSERT(offsetof(oils_packet_header, step) == 24, "oils_packet_header.step offset");
OILS_STATIC_ASSERT(offsetof(oils_packet_header, t_ns) == 32, "oils_packet_header.t_ns offset");
OILS_STATIC_ASSERT(sizeof(oils_packet_header) == 40, "oils_packet_header size");
OILS_STATIC_ASSERT(offsetof(oils_nav_state, pos_mci_m) == 0, "oils_nav_state.pos_mci_m offset");
OILS_STATIC_ASSERT(offsetof(oils_nav_state, vel_mci_m_s) == 24, "oils_nav_state.vel_mci_m_s offset");
OILS_STATIC_ASSERT(offsetof(oils_nav_state, q_mci_from_body) == 48, "oils_nav_state.q_mci_from_body offset");
OILS_STATIC_ASSERT(offsetof(oils_nav_state, rate_body_rad_s) == 80, "oils_nav_state.rate_body_rad_s offset");
OILS_STATIC_ASSERT(sizeof(oils_nav_state) == 104, "oils_nav_state size");
OILS_STATIC_ASSERT(offsetof(oils_engine_reading, thrust_n) == 0, "oils_engine_reading.thrust_n offset");
OILS_STATIC_ASSERT(offsetof(oils_engine_reading, chamber_pressure_pa) == 8, "oils_engine_reading.chamber_pressure_pa offset");
OILS_STATIC_ASSERT(offsetof(oils_engine_reading, valve_open) == 16, "oils_engine_reading.valve_open offset");
OILS_STATIC_ASSERT(offsetof(oils_engine_reading, flags) == 20, "oils_engine_reading.flags offset");
OILS_STATIC_ASSERT(sizeof(oils_engine_reading) == 24, "oils_engine_reading size");
OILS_STATIC_ASSERT(offsetof(oils_propulsion_readings, gas_pressure_pa) == 0, "oils_propulsion_readings.gas_pressure_pa offset");
OILS_STATIC_ASSERT(offsetof(oils_propulsion_readings, fuel_tank_pressure_pa) == 8, "oils_propulsion_readings.fuel_tank_pressure_pa offset");
OILS_STATIC_ASSERT(offsetof(oils_propulsion_readings, ox_tank_pressure_pa) == 16, "oils_propulsion_readings.ox_tank_pressure_pa offset");
OILS_STATIC_ASSERT(offsetof(oils_propulsion_readings, engines) == 24, "oils_propulsion_readings.engines offset");
OILS_STATIC_ASSERT(sizeof(oils_propulsion_readings) == 120, "oils_propulsion_readings size");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, header) == 0, "oils_telemetry.header offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, nav) == 40, "oils_telemetry.nav offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, accel_body_m_s2) == 144, "oils_telemetry.accel_body_m_s2 offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, altitude_m) == 168, "oils_telemetry.altitude_m offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, mass_estimate_kg) == 176, "oils_telemetry.mass_estimate_kg offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, propulsion) == 184, "oils_telemetry.propulsion offset");
OILS_STATIC_ASSERT(sizeof(oils_telemetry) == 304, "oils_telemetry size");
OILS_STATIC_ASSERT(offsetof(oils_command, header) == 0, "oils_command.header offset");
OILS_STATIC_ASSERT(offsetof(oils_command, thrust_cmd_n) == 40, "oils_command.thrust_cmd_n offset");
OILS_STATIC_ASSERT(offsetof(oils_command, engine_on) == 72, "oils_command.engine_on offset");
OILS_STATIC_ASSERT(offsetof(oils_command, torque_cmd_body_nm) == 88, "oils_command.torque_cmd_body_nm offset");
OILS_STATIC_ASSERT(offsetof(oils_command, stub_compute_ns) == 112, "oils_command.stub_compute_ns offset");
OILS_STATIC_ASSERT(sizeof(oils_command) == 120, "oils_command size");
OILS_STATIC_ASSERT(offsetof(oils_fsw_config, abi_version) == 0, "oils_fsw_config.abi_version offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_config, protocol_version) == 4, "oils_fsw_config.protocol_version offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_config, schema_hash) == 8, "oils_fsw_config.schema_hash offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_config, run_id) == 16, "oils_fsw_config.run_id offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_config, params) == 24, "oils_fsw_config.params offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_config, params_len) == 32, "oils_fsw_config.params_len offset");
OILS_STATIC_ASSERT(sizeof(oils_fsw_config) == 40, "oils_fsw_config size");

/* The flight-software ABI. Export these five from your shared library. */

/* Return OILS_FSW_ABI_VERSION and OILS_FSW_LAYOUT_HASH as compiled: the loader
 * refuses a library built against another header. */
uint32_t oils_fsw_abi_version(void);
uint64_t oils_fsw_layout_hash(void);

/* Called once before tick 0: allocate everything here. Return your context (any
 * non-NULL pointer), or NULL to refuse the run (the stub exits with an error). */
void *oils_fsw_init(const oils_fsw_config *config);

/* Called once per step with Telemetry(k): fill cmd->thrust_cmd_n, cmd->engine_on
 * (0/1) and cmd->torque_cmd_body_nm (cmd arrives zeroed; the stub stamps the header
 * and stub_compute_ns). Must not block, allocate or read the wall clock: simulated
 * time is tlm->header.t_ns. Return OILS_FSW_STATUS_OK, or any other value to stop
 * the run with that error code. */
int32_t oils_fsw_step(void *ctx, const oils_telemetry *tlm, oils_command *cmd);

/* Called once after the last step (also after a failed step): free the context. */
void oils_fsw_fini(void *ctx);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* OILS_H */
