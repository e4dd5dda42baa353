/* oils.h: the oils bench's wire packets and flight-software C ABI, v2.
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

#define OILS_PROTOCOL_VERSION 4u
#define OILS_SCHEMA_HASH UINT64_C(0x4a5af273d1422863)
#define OILS_FSW_ABI_VERSION 2u
#define OILS_FSW_LAYOUT_HASH UINT64_C(0xb7367e4057532798)
#define OILS_ENGINE_COUNT 4
#define OILS_TLM_FLAG_END_OF_RUN 1u /* last telemetry: answer nothing */
#define OILS_TLM_FLAG_NAV_NOISE 2u  /* nav values carry seeded noise */
#define OILS_TLM_FLAG_FOOTPAD_CONTACT 4u  /* a footpad touches the ground: engines off */
#define OILS_TLM_FLAG_IDEAL_NAV 8u  /* nav, accel_body_m_s2, altitude_m are filled */
#define OILS_TLM_FLAG_SENSORS 16u  /* sensors holds the device samples */
#define OILS_TLM_FLAG_STATE_VECTOR 32u  /* nav holds the ground's state vector to start from */
#define OILS_TLM_FLAG_COMPUTER_RESET 64u  /* the computer is resetting: state is lost */
#define OILS_NAV_FLAG_VALID 1u
#define OILS_NAV_FLAG_FROM_SENSORS 2u
#define OILS_NAV_FLAG_STAR_TRACKER_USED 4u
#define OILS_NAV_FLAG_LASER_USED 8u
#define OILS_NAV_FLAG_RF_USED 16u
#define OILS_NAV_FLAG_VELOCIMETER_USED 32u
#define OILS_NAV_FLAG_LASER_LOST 64u
#define OILS_NAV_FLAG_REINIT 128u
#define OILS_NAV_FLAG_TERRAIN_USED 256u
#define OILS_NAV_FLAG_TERRAIN_LOST 512u
#define OILS_NAV_FLAG_HAZARD_MAPPED 1024u
#define OILS_NAV_FLAG_HAZARD_UNMAPPED 2048u
#define OILS_RATE_GROUPS 4
#define OILS_THRUSTER_COUNT 8
#define OILS_VELOCIMETER_BEAMS 3
#define OILS_IMU_SAMPLES_MAX 8
#define OILS_STAR_TRACKER_SAMPLES_MAX 2
#define OILS_ALTIMETER_SAMPLES_MAX 2
#define OILS_VELOCIMETER_SAMPLES_MAX 2
#define OILS_SAMPLE_FLAG_SATURATED 1u
#define OILS_SAMPLE_FLAG_NO_LOCK 2u
#define OILS_SAMPLE_FLAG_INHIBITED 4u
#define OILS_SAMPLE_FLAG_OUTAGE 8u
#define OILS_FRAMES_MAX 4
#define OILS_FRAME_DEVICE_CAMERA 1u
#define OILS_FRAME_DEVICE_LIDAR 2u
#define OILS_FRAME_DEVICE_TEST_CARD 3u
#define OILS_FRAME_FORMAT_U16_LE 1u  /* uint16 little-endian DN, row-major */
#define OILS_FRAME_FORMAT_F32_LE_M 2u  /* float32 little-endian range, metres; 0 = no return */
#define OILS_FRAME_FLAG_SATURATED 1u
#define OILS_FRAME_FLAG_OUTAGE 2u
#define OILS_FRAME_FLAG_FROZEN 4u
#define OILS_ATTITUDE_MODE_IDEAL_TORQUE 0u
#define OILS_ATTITUDE_MODE_THRUSTERS 1u
#define OILS_FSW_STATUS_OK 0 /* any other value from oils_fsw_step stops the run */

/* The schema string whose FNV-1a 64 hash is OILS_SCHEMA_HASH. */
#define OILS_SCHEMA \
  "PacketHeader{protocol_version:u32@0,flags:u32@4,schema_hash:u64@8,run_id:u64@16,step:u64@24,t_ns:i64@32}=40|" \
  "NavState{pos_mci_m:[f64;3]@0,vel_mci_m_s:[f64;3]@24,q_mci_from_body:[f64;4]@48,rate_body_rad_s:[f64;3]@80}=104|" \
  "EngineReading{thrust_n:f64@0,chamber_pressure_pa:f64@8,valve_open:u32@16,flags:u32@20}=24|" \
  "PropulsionReadings{gas_pressure_pa:f64@0,fuel_tank_pressure_pa:f64@8,ox_tank_pressure_pa:f64@16,engines:[EngineReading;4]@24}=120|" \
  "ImuSample{t_ns:i64@0,delta_v_body_m_s:[f64;3]@8,delta_theta_body_rad:[f64;3]@32,valid:u32@56,flags:u32@60}=64|" \
  "StarTrackerSample{t_ns:i64@0,q_mci_from_body:[f64;4]@8,valid:u32@40,flags:u32@44}=48|" \
  "AltimeterSample{t_ns:i64@0,range_m:f64@8,valid:u32@16,flags:u32@20}=24|" \
  "VelocimeterSample{t_ns:i64@0,los_velocity_m_s:[f64;3]@8,range_m:[f64;3]@32,valid:[u32;3]@56,flags:u32@68}=72|" \
  "FrameAnnouncement{device:u32@0,format:u32@4,width:u32@8,height:u32@12,seq:u64@16,t_ns:i64@24,exposure_ns:u64@32,bytes:u32@40,flags:u32@44,hash:u64@48}=56|" \
  "SensorFrame{imu_count:u32@0,star_tracker_count:u32@4,laser_altimeter_count:u32@8,rf_altimeter_count:u32@12,velocimeter_count:u32@16,frame_count:u32@20,imu:[ImuSample;8]@24,star_tracker:[StarTrackerSample;2]@536,laser_altimeter:[AltimeterSample;2]@632,rf_altimeter:[AltimeterSample;2]@680,velocimeter:[VelocimeterSample;2]@728,frames:[FrameAnnouncement;4]@872}=1096|" \
  "Telemetry{header:PacketHeader@0,nav:NavState@40,accel_body_m_s2:[f64;3]@144,altitude_m:f64@168,mass_estimate_kg:f64@176,propulsion:PropulsionReadings@184,sensors:SensorFrame@304}=1400|" \
  "FswReport{nav_pos_mci_m:[f64;3]@0,nav_vel_mci_m_s:[f64;3]@24,nav_pos_sigma_m:[f64;3]@48,nav_vel_sigma_m_s:[f64;3]@72,nav_altitude_m:f64@96,nav_altitude_sigma_m:f64@104,group_compute_ns:[u32;4]@112,nav_flags:u32@128,phase:u32@132,boot_count:u32@136,cycle_slips:u32@140}=144|" \
  "Command{header:PacketHeader@0,thrust_cmd_n:[f64;4]@40,engine_on:[u32;4]@72,torque_cmd_body_nm:[f64;3]@88,stub_compute_ns:u64@112,thruster_on_time_ns:[u64;8]@120,attitude_mode:u32@184,reserved:u32@188,fsw:FswReport@192}=336|"

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

typedef struct oils_imu_sample {
  int64_t t_ns;
  double delta_v_body_m_s[3];
  double delta_theta_body_rad[3];
  uint32_t valid;
  uint32_t flags;
} oils_imu_sample;

typedef struct oils_star_tracker_sample {
  int64_t t_ns;
  double q_mci_from_body[4];
  uint32_t valid;
  uint32_t flags;
} oils_star_tracker_sample;

typedef struct oils_altimeter_sample {
  int64_t t_ns;
  double range_m;
  uint32_t valid;
  uint32_t flags;
} oils_altimeter_sample;

typedef struct oils_velocimeter_sample {
  int64_t t_ns;
  double los_velocity_m_s[3];
  double range_m[3];
  uint32_t valid[3];
  uint32_t flags;
} oils_velocimeter_sample;

typedef struct oils_frame_announcement {
  uint32_t device;
  uint32_t format;
  uint32_t width;
  uint32_t height;
  uint64_t seq;
  int64_t t_ns;
  uint64_t exposure_ns;
  uint32_t bytes;
  uint32_t flags;
  uint64_t hash;
} oils_frame_announcement;

typedef struct oils_sensor_frame {
  uint32_t imu_count;
  uint32_t star_tracker_count;
  uint32_t laser_altimeter_count;
  uint32_t rf_altimeter_count;
  uint32_t velocimeter_count;
  uint32_t frame_count;
  oils_imu_sample imu[8];
  oils_star_tracker_sample star_tracker[2];
  oils_altimeter_sample laser_altimeter[2];
  oils_altimeter_sample rf_altimeter[2];
  oils_velocimeter_sample velocimeter[2];
  oils_frame_announcement frames[4];
} oils_sensor_frame;

typedef struct oils_telemetry {
  oils_packet_header header;
  oils_nav_state nav;
  double accel_body_m_s2[3];
  double altitude_m;
  double mass_estimate_kg;
  oils_propulsion_readings propulsion;
  oils_sensor_frame sensors;
} oils_telemetry;

typedef struct oils_fsw_report {
  double nav_pos_mci_m[3];
  double nav_vel_mci_m_s[3];
  double nav_pos_sigma_m[3];
  double nav_vel_sigma_m_s[3];
  double nav_altitude_m;
  double nav_altitude_sigma_m;
  uint32_t group_compute_ns[4];
  uint32_t nav_flags;
  uint32_t phase;
  uint32_t boot_count;
  uint32_t cycle_slips;
} oils_fsw_report;

typedef struct oils_command {
  oils_packet_header header;
  double thrust_cmd_n[4];
  uint32_t engine_on[4];
  double torque_cmd_body_nm[3];
  uint64_t stub_compute_ns;
  uint64_t thruster_on_time_ns[8];
  uint32_t attitude_mode;
  uint32_t reserved;
  oils_fsw_report fsw;
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
OILS_STATIC_ASSERT(offsetof(oils_imu_sample, t_ns) == 0, "oils_imu_sample.t_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_imu_sample, delta_v_body_m_s) == 8, "oils_imu_sample.delta_v_body_m_s offset");
OILS_STATIC_ASSERT(offsetof(oils_imu_sample, delta_theta_body_rad) == 32, "oils_imu_sample.delta_theta_body_rad offset");
OILS_STATIC_ASSERT(offsetof(oils_imu_sample, valid) == 56, "oils_imu_sample.valid offset");
OILS_STATIC_ASSERT(offsetof(oils_imu_sample, flags) == 60, "oils_imu_sample.flags offset");
OILS_STATIC_ASSERT(sizeof(oils_imu_sample) == 64, "oils_imu_sample size");
OILS_STATIC_ASSERT(offsetof(oils_star_tracker_sample, t_ns) == 0, "oils_star_tracker_sample.t_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_star_tracker_sample, q_mci_from_body) == 8, "oils_star_tracker_sample.q_mci_from_body offset");
OILS_STATIC_ASSERT(offsetof(oils_star_tracker_sample, valid) == 40, "oils_star_tracker_sample.valid offset");
OILS_STATIC_ASSERT(offsetof(oils_star_tracker_sample, flags) == 44, "oils_star_tracker_sample.flags offset");
OILS_STATIC_ASSERT(sizeof(oils_star_tracker_sample) == 48, "oils_star_tracker_sample size");
OILS_STATIC_ASSERT(offsetof(oils_altimeter_sample, t_ns) == 0, "oils_altimeter_sample.t_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_altimeter_sample, range_m) == 8, "oils_altimeter_sample.range_m offset");
OILS_STATIC_ASSERT(offsetof(oils_altimeter_sample, valid) == 16, "oils_altimeter_sample.valid offset");
OILS_STATIC_ASSERT(offsetof(oils_altimeter_sample, flags) == 20, "oils_altimeter_sample.flags offset");
OILS_STATIC_ASSERT(sizeof(oils_altimeter_sample) == 24, "oils_altimeter_sample size");
OILS_STATIC_ASSERT(offsetof(oils_velocimeter_sample, t_ns) == 0, "oils_velocimeter_sample.t_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_velocimeter_sample, los_velocity_m_s) == 8, "oils_velocimeter_sample.los_velocity_m_s offset");
OILS_STATIC_ASSERT(offsetof(oils_velocimeter_sample, range_m) == 32, "oils_velocimeter_sample.range_m offset");
OILS_STATIC_ASSERT(offsetof(oils_velocimeter_sample, valid) == 56, "oils_velocimeter_sample.valid offset");
OILS_STATIC_ASSERT(offsetof(oils_velocimeter_sample, flags) == 68, "oils_velocimeter_sample.flags offset");
OILS_STATIC_ASSERT(sizeof(oils_velocimeter_sample) == 72, "oils_velocimeter_sample size");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, device) == 0, "oils_frame_announcement.device offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, format) == 4, "oils_frame_announcement.format offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, width) == 8, "oils_frame_announcement.width offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, height) == 12, "oils_frame_announcement.height offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, seq) == 16, "oils_frame_announcement.seq offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, t_ns) == 24, "oils_frame_announcement.t_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, exposure_ns) == 32, "oils_frame_announcement.exposure_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, bytes) == 40, "oils_frame_announcement.bytes offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, flags) == 44, "oils_frame_announcement.flags offset");
OILS_STATIC_ASSERT(offsetof(oils_frame_announcement, hash) == 48, "oils_frame_announcement.hash offset");
OILS_STATIC_ASSERT(sizeof(oils_frame_announcement) == 56, "oils_frame_announcement size");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, imu_count) == 0, "oils_sensor_frame.imu_count offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, star_tracker_count) == 4, "oils_sensor_frame.star_tracker_count offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, laser_altimeter_count) == 8, "oils_sensor_frame.laser_altimeter_count offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, rf_altimeter_count) == 12, "oils_sensor_frame.rf_altimeter_count offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, velocimeter_count) == 16, "oils_sensor_frame.velocimeter_count offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, frame_count) == 20, "oils_sensor_frame.frame_count offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, imu) == 24, "oils_sensor_frame.imu offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, star_tracker) == 536, "oils_sensor_frame.star_tracker offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, laser_altimeter) == 632, "oils_sensor_frame.laser_altimeter offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, rf_altimeter) == 680, "oils_sensor_frame.rf_altimeter offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, velocimeter) == 728, "oils_sensor_frame.velocimeter offset");
OILS_STATIC_ASSERT(offsetof(oils_sensor_frame, frames) == 872, "oils_sensor_frame.frames offset");
OILS_STATIC_ASSERT(sizeof(oils_sensor_frame) == 1096, "oils_sensor_frame size");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, header) == 0, "oils_telemetry.header offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, nav) == 40, "oils_telemetry.nav offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, accel_body_m_s2) == 144, "oils_telemetry.accel_body_m_s2 offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, altitude_m) == 168, "oils_telemetry.altitude_m offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, mass_estimate_kg) == 176, "oils_telemetry.mass_estimate_kg offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, propulsion) == 184, "oils_telemetry.propulsion offset");
OILS_STATIC_ASSERT(offsetof(oils_telemetry, sensors) == 304, "oils_telemetry.sensors offset");
OILS_STATIC_ASSERT(sizeof(oils_telemetry) == 1400, "oils_telemetry size");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, nav_pos_mci_m) == 0, "oils_fsw_report.nav_pos_mci_m offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, nav_vel_mci_m_s) == 24, "oils_fsw_report.nav_vel_mci_m_s offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, nav_pos_sigma_m) == 48, "oils_fsw_report.nav_pos_sigma_m offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, nav_vel_sigma_m_s) == 72, "oils_fsw_report.nav_vel_sigma_m_s offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, nav_altitude_m) == 96, "oils_fsw_report.nav_altitude_m offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, nav_altitude_sigma_m) == 104, "oils_fsw_report.nav_altitude_sigma_m offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, group_compute_ns) == 112, "oils_fsw_report.group_compute_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, nav_flags) == 128, "oils_fsw_report.nav_flags offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, phase) == 132, "oils_fsw_report.phase offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, boot_count) == 136, "oils_fsw_report.boot_count offset");
OILS_STATIC_ASSERT(offsetof(oils_fsw_report, cycle_slips) == 140, "oils_fsw_report.cycle_slips offset");
OILS_STATIC_ASSERT(sizeof(oils_fsw_report) == 144, "oils_fsw_report size");
OILS_STATIC_ASSERT(offsetof(oils_command, header) == 0, "oils_command.header offset");
OILS_STATIC_ASSERT(offsetof(oils_command, thrust_cmd_n) == 40, "oils_command.thrust_cmd_n offset");
OILS_STATIC_ASSERT(offsetof(oils_command, engine_on) == 72, "oils_command.engine_on offset");
OILS_STATIC_ASSERT(offsetof(oils_command, torque_cmd_body_nm) == 88, "oils_command.torque_cmd_body_nm offset");
OILS_STATIC_ASSERT(offsetof(oils_command, stub_compute_ns) == 112, "oils_command.stub_compute_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_command, thruster_on_time_ns) == 120, "oils_command.thruster_on_time_ns offset");
OILS_STATIC_ASSERT(offsetof(oils_command, attitude_mode) == 184, "oils_command.attitude_mode offset");
OILS_STATIC_ASSERT(offsetof(oils_command, reserved) == 188, "oils_command.reserved offset");
OILS_STATIC_ASSERT(offsetof(oils_command, fsw) == 192, "oils_command.fsw offset");
OILS_STATIC_ASSERT(sizeof(oils_command) == 336, "oils_command size");
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

/* Called once per cycle with Telemetry(k): fill cmd->thrust_cmd_n, cmd->engine_on
 * (0/1), and cmd->torque_cmd_body_nm (attitude_mode 0) or cmd->thruster_on_time_ns
 * (attitude_mode 1) (cmd arrives zeroed; the stub stamps the header
 * and stub_compute_ns). Must not block, allocate or read the wall clock: simulated
 * time is tlm->header.t_ns. Return OILS_FSW_STATUS_OK, or any other value to stop
 * the run with that error code. */
int32_t oils_fsw_step(void *ctx, const oils_telemetry *tlm, oils_command *cmd);

/* Called once after the last step (also after a failed step): free the context. */
void oils_fsw_fini(void *ctx);

/* Optional (ABI v2): called before oils_fsw_step once per frame that telemetry
 * announces (tlm->sensors.frames), with the frame's pixels in shared memory: len ==
 * ann->bytes bytes, read-only, valid until this call returns (copy what you keep).
 * Must not block or allocate. Return OILS_FSW_STATUS_OK, or any other value to stop
 * the run. A library that does not export it never sees frames. */
int32_t oils_fsw_frame(void *ctx, const oils_frame_announcement *ann,
                       const uint8_t *pixels, size_t len);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* OILS_H */
