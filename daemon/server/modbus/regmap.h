/*
 * regmap.h -- the Modbus register map of luxradd: the one definition of
 * every register a Modbus client can read, and the encoders that turn
 * values into register words.
 *
 * The map is three blocks of read-only INPUT registers (function 0x04),
 * at fixed addresses that do not depend on the configuration:
 *   daemon   MB_DAEMON_BASE, MB_DAEMON_REGS registers;
 *   jobs     MB_JOB_BASE + MB_JOB_STRIDE * k, for slot k < job_slots;
 *   sensors  MB_SENSOR_BASE + MB_SENSOR_STRIDE * k, k < sensor_slots.
 * Only the slot counts are configured (at most MB_JOB_SLOTS_MAX and
 * MB_SENSOR_SLOTS_MAX), so a client's addresses stay valid when an
 * operator adds slots.  Addresses outside the configured blocks are not
 * registers (a read touching one gets ILLEGAL DATA ADDRESS).
 *
 * Each block is an X-macro table below: X(NAME, offset, registers, type,
 * unit, avail, description).  Offsets are written out so the header reads
 * as the map; the static_asserts in regmap.c prove that they are
 * contiguous and match the registers each type needs, and MODBUS.md's
 * table is generated from these tables (mb_map_write_markdown) and
 * checked by a test, so code and document cannot drift apart.
 *
 * Encoding.  A register is a 16-bit word (libmodbus puts its high byte
 * first on the wire).  32-bit values take two consecutive registers in
 * the configured word order: ABCD puts the high word first, CDAB the low
 * word first.  The encoders here are ours: libmodbus 3.1.6's float
 * helpers swap bytes on little-endian machines (docs/PITFALLS.md).
 * A value that is not available reads as its type's sentinel: u16 and
 * scaled u16 0xFFFF, u32 0xFFFFFFFF, i32 0x80000000, f32 quiet NaN
 * (0x7FC00000); real values are clipped below the sentinel (a u16 never
 * reads above 65534 unless unavailable, a u32 never above 0xFFFFFFFE).
 */
#ifndef LUXRAD_SRV_REGMAP_H
#define LUXRAD_SRV_REGMAP_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#define MB_MAP_VERSION 1

/* Word order of 32-bit values (modbus_word_order). */
typedef enum mb_word_order {
	MB_ABCD = 0, /* high word first ("big endian"; mbpoll -B) */
	MB_CDAB = 1  /* low word first (mbpoll's default) */
} mb_word_order;

/* Register types: X(NAME, registers, doc name, sentinel text). */
#define MB_TYPES(X)                                                            \
	X(U16, 1, "u16", "0xFFFF")                                             \
	X(U32, 2, "u32", "0xFFFFFFFF")                                         \
	X(I32, 2, "i32", "0x80000000")                                         \
	X(F32, 2, "f32", "NaN")                                                \
	X(U16S, 1, "u16 scaled", "0xFFFF")                                     \
	X(STR, 0, "ASCII", "all 0")

typedef enum mb_type {
#define MB_TYPE_ENUM_(name, regs, doc, sentinel) MB_##name,
	MB_TYPES(MB_TYPE_ENUM_)
#undef MB_TYPE_ENUM_
	        MB_NTYPES
} mb_type;

/* Whether a field can read as its sentinel. */
typedef enum mb_avail {
	MB_ALWAYS = 0, /* always holds a value (in an empty slot too) */
	MB_MAYBE       /* sentinel until published / in an empty slot */
} mb_avail;

/* ------------------------------------------------------------ the blocks */

#define MB_DAEMON_BASE 0
#define MB_DAEMON_MAP(X)                                                       \
	X(MAP_VERSION, 0, 1, U16, "", ALWAYS,                                  \
	  "Register map version (this document describes 1)")                  \
	X(JOB_SLOTS, 1, 1, U16, "", ALWAYS,                                    \
	  "Job slots served (`modbus_job_slots`)")                             \
	X(SENSOR_SLOTS, 2, 1, U16, "", ALWAYS,                                 \
	  "Sensor slots served (`modbus_sensor_slots`)")                       \
	X(WORD_ORDER, 3, 1, U16, "", ALWAYS,                                   \
	  "Word order of 32-bit values: 0 = ABCD, 1 = CDAB")                   \
	X(FLOAT_PROBE, 4, 2, F32, "", ALWAYS,                                  \
	  "Always 1.0: reads 0x3F80 0x0000 in ABCD, 0x0000 0x3F80 in CDAB")    \
	X(LUX_SCALE, 6, 2, F32, "", ALWAYS,                                    \
	  "Factor of the scaled lux registers (`modbus_lux_scale`)")           \
	X(UPTIME, 8, 2, U32, "s", MAYBE, "Seconds since the daemon started")   \
	X(JOBS_QUEUED, 10, 1, U16, "jobs", ALWAYS, "Jobs queued")              \
	X(JOBS_RUNNING, 11, 1, U16, "jobs", ALWAYS, "Jobs running")            \
	X(JOBS_PAUSED, 12, 1, U16, "jobs", ALWAYS, "Jobs paused")              \
	X(JOBS_DONE, 13, 1, U16, "jobs", ALWAYS, "Jobs done")                  \
	X(JOBS_FAILED, 14, 1, U16, "jobs", ALWAYS, "Jobs failed")              \
	X(JOBS_CANCELLED, 15, 1, U16, "jobs", ALWAYS, "Jobs cancelled")        \
	X(JOBS_UNSLOTTED, 16, 1, U16, "jobs", ALWAYS,                          \
	  "Jobs without a slot (more jobs than slots)")                        \
	X(SENSORS_UNSLOTTED, 17, 1, U16, "sensors", ALWAYS,                    \
	  "Sensors without a slot")                                            \
	X(MEMORY, 18, 2, U32, "KiB", MAYBE,                                    \
	  "Memory held by scenes, jobs and solutions")                         \
	X(MODBUS_CLIENTS, 20, 1, U16, "clients", ALWAYS,                       \
	  "Modbus clients connected now")

#define MB_JOB_BASE 1000
#define MB_JOB_MAP(X)                                                          \
	X(JOB_ID, 0, 2, U32, "", ALWAYS, "Job id; 0 = empty slot")             \
	X(STATE, 2, 1, U16, "", ALWAYS, "Job state (table below)")             \
	X(PROGRESS, 3, 1, U16, "‰", MAYBE,                                     \
	  "Progress of the current run, per mille (0..1000)")                  \
	X(ITERATION, 4, 2, U32, "", MAYBE, "Iterations done")                  \
	X(RESIDUAL, 6, 2, F32, "", MAYBE, "Residual of the last iteration")    \
	X(ERROR_ESTIMATE, 8, 2, F32, "", MAYBE,                                \
	  "Estimated remaining relative error")                                \
	X(LINKS, 10, 2, U32, "links", MAYBE, "Links stored")                   \
	X(MEMORY, 12, 2, U32, "KiB", MAYBE, "Memory held by the job")          \
	X(ELAPSED, 14, 2, U32, "s", MAYBE, "Seconds spent solving")            \
	X(ETA, 16, 2, U32, "s", MAYBE, "Estimated seconds left")               \
	X(SCENE_ID, 18, 2, U32, "", MAYBE, "Scene the job solves")

#define MB_SENSOR_BASE 3000
#define MB_SENSOR_MAP(X)                                                       \
	X(JOB_ID, 0, 2, U32, "", ALWAYS,                                       \
	  "Job whose solution the value comes from; 0 = empty slot")           \
	X(LUX, 2, 2, F32, "lx", MAYBE, "Illuminance")                          \
	X(ITERATION, 4, 2, U32, "", MAYBE, "Iteration the value comes from")   \
	X(STATUS, 6, 1, U16, "", ALWAYS, "Sensor status (table below)")        \
	X(LUX_SCALED, 7, 1, U16S, "lx × scale", MAYBE,                         \
	  "round(lux × lux_scale), clipped to 0..65534")                       \
	X(NAME, 8, 8, STR, "", ALWAYS,                                         \
	  "Name: 2 bytes per register, first byte high, NUL-padded, the "      \
	  "first 16 bytes")

/* Offsets within a block or slot: MB_D_UPTIME, MB_J_ITERATION... */
enum {
#define MB_OFF_(name, off, regs, type, unit, avail, desc) MB_D_##name = off,
	MB_DAEMON_MAP(MB_OFF_)
#undef MB_OFF_
#define MB_OFF_(name, off, regs, type, unit, avail, desc) MB_J_##name = off,
	        MB_JOB_MAP(MB_OFF_)
#undef MB_OFF_
#define MB_OFF_(name, off, regs, type, unit, avail, desc) MB_S_##name = off,
	                MB_SENSOR_MAP(MB_OFF_)
#undef MB_OFF_
};

/* Block sizes (asserted against the tables in regmap.c). */
#define MB_DAEMON_REGS 21
#define MB_JOB_STRIDE 20
#define MB_SENSOR_STRIDE 16
#define MB_JOB_SLOTS_MAX 64
#define MB_SENSOR_SLOTS_MAX 1024
#define MB_NAME_BYTES 16 /* name bytes a sensor slot shows */
/* One past the last address any configuration can serve. */
#define MB_ADDR_END (MB_SENSOR_BASE + MB_SENSOR_STRIDE * MB_SENSOR_SLOTS_MAX)

/* Job states as the STATE register shows them: X(NAME, value, doc). */
#define MB_JOB_STATES(X)                                                       \
	X(EMPTY, 0, "empty slot")                                              \
	X(QUEUED, 1, "queued")                                                 \
	X(RUNNING, 2, "running")                                               \
	X(PAUSED, 3, "paused")                                                 \
	X(DONE, 4, "done")                                                     \
	X(FAILED, 5, "failed")                                                 \
	X(CANCELLED, 6, "cancelled")

typedef enum mb_job_state {
#define MB_JS_ENUM_(name, v, doc) MB_JOB_##name = v,
	MB_JOB_STATES(MB_JS_ENUM_)
#undef MB_JS_ENUM_
	        MB_JOB_NSTATES
} mb_job_state;

/* Sensor slot status: X(NAME, value, doc). */
#define MB_SENSOR_STATUSES(X)                                                  \
	X(EMPTY, 0, "empty slot")                                              \
	X(WAITING, 1,                                                          \
	  "declared, no value yet (lux registers read NaN / "                  \
	  "0xFFFF)")                                                           \
	X(VALID, 2, "value from the iteration shown")

typedef enum mb_sensor_status {
#define MB_SS_ENUM_(name, v, doc) MB_SENSOR_##name = v,
	MB_SENSOR_STATUSES(MB_SS_ENUM_)
#undef MB_SS_ENUM_
} mb_sensor_status;

/* -------------------------------------------------------------- encoders */

#define MB_U16_NA 0xFFFFu
#define MB_U32_NA 0xFFFFFFFFu
#define MB_I32_NA INT32_MIN

/* Registers a field of this type takes (STR: given by the table). */
int mb_type_regs(mb_type t);
const char *mb_type_name(mb_type t);
/* Parse / name a word order ("abcd" / "cdab", any case). 0 or -1. */
int mb_word_order_parse(const char *s, mb_word_order *out);
const char *mb_word_order_name(mb_word_order wo);

/* A u32 split into two registers in word order wo, and back. */
void mb_put_u32(uint16_t r[2], uint32_t v, mb_word_order wo);
uint32_t mb_get_u32(const uint16_t r[2], mb_word_order wo);
void mb_put_i32(uint16_t r[2], int32_t v, mb_word_order wo);
int32_t mb_get_i32(const uint16_t r[2], mb_word_order wo);
/* IEEE 754 binary32; NaN is written as the canonical quiet NaN. */
void mb_put_f32(uint16_t r[2], float v, mb_word_order wo);
float mb_get_f32(const uint16_t r[2], mb_word_order wo);
/* The first 2 * nregs bytes of s, NUL-padded, first byte high. */
void mb_put_str(uint16_t *r, size_t nregs, const char *s);

/* Saturating conversions that keep the sentinel free. */
uint16_t mb_u16_of(uint64_t v); /* min(v, 65534) */
uint32_t mb_u32_of(uint64_t v); /* min(v, 0xFFFFFFFE) */
/* Seconds (or any count) as u32: NaN or negative -> MB_U32_NA, rounded,
 * clipped to 0xFFFFFFFE. */
uint32_t mb_u32_of_double(double v);
/* Bytes as KiB (rounded up), clipped; negative -> MB_U32_NA. */
uint32_t mb_kib_of_bytes(int64_t bytes);
/* Fraction 0..1 as per mille (rounded, clipped to 0..1000); NaN ->
 * MB_U16_NA. */
uint16_t mb_permille_of(double fraction);
/* round(lux x scale) clipped to 0..65534; NaN lux -> MB_U16_NA. */
uint16_t mb_lux_scaled(double lux, double scale);

/* ----------------------------------------------------------- the document */

/* Write MODBUS.md's generated section (the tables) to f.  0 or -1. */
int mb_map_write_markdown(FILE *f);

#endif
