/*
 * regmap.c -- the register map's compile-time checks, the value encoders
 * and the Markdown tables of MODBUS.md, all from the X-macro tables of
 * regmap.h.
 *
 * DESIGN
 * Contiguity is proven by the compiler: each block's table becomes a
 * struct of uint16_t arrays (one per field, as many as the field's
 * registers); arrays of uint16_t are laid out without padding, so a
 * field's written offset must equal its offsetof() / 2, and the struct's
 * size is the block's register count.  A gap, an overlap, a wrong size
 * or a 32-bit type given one register fails the build.
 *
 * Encoders work on register values (host uint16_t); libmodbus turns each
 * into two bytes, high first, when it answers.  Floats go through memcpy
 * to their IEEE bit pattern, so the result does not depend on the host's
 * byte order.
 */
#include "regmap.h"

#include <assert.h>
#include <ctype.h>
#include <math.h>
#include <string.h>
#include <strings.h>

/* ----------------------------------------------------- compile-time map */

enum {
#define REGS_(name, regs, doc, sentinel) REGS_##name = regs,
	MB_TYPES(REGS_)
#undef REGS_
};

#define FIELD_(name, off, regs, type, unit, avail, desc) uint16_t name[regs];
struct daemon_layout {
	MB_DAEMON_MAP(FIELD_)
};
struct job_layout {
	MB_JOB_MAP(FIELD_)
};
struct sensor_layout {
	MB_SENSOR_MAP(FIELD_)
};
#undef FIELD_

#define CHECK_(layout, name, off, regs, type)                                  \
	static_assert(offsetof(struct layout, name) == 2 * (off),              \
	              #layout " " #name ": offset does not follow the field "  \
	                      "before it");                                    \
	static_assert(REGS_##type == 0 || REGS_##type == (regs),               \
	              #layout " " #name ": register count does not fit "       \
	                      "the type");
#define CHECK_D_(name, off, regs, type, unit, avail, desc)                     \
	CHECK_(daemon_layout, name, off, regs, type)
#define CHECK_J_(name, off, regs, type, unit, avail, desc)                     \
	CHECK_(job_layout, name, off, regs, type)
#define CHECK_S_(name, off, regs, type, unit, avail, desc)                     \
	CHECK_(sensor_layout, name, off, regs, type)
MB_DAEMON_MAP(CHECK_D_)
MB_JOB_MAP(CHECK_J_)
MB_SENSOR_MAP(CHECK_S_)
#undef CHECK_D_
#undef CHECK_J_
#undef CHECK_S_
#undef CHECK_

static_assert(sizeof(struct daemon_layout) == 2 * MB_DAEMON_REGS,
              "MB_DAEMON_REGS does not match the daemon table");
static_assert(sizeof(struct job_layout) == 2 * MB_JOB_STRIDE,
              "MB_JOB_STRIDE does not match the job table");
static_assert(sizeof(struct sensor_layout) == 2 * MB_SENSOR_STRIDE,
              "MB_SENSOR_STRIDE does not match the sensor table");
static_assert(MB_DAEMON_BASE + MB_DAEMON_REGS <= MB_JOB_BASE,
              "the daemon block runs into the job slots");
static_assert(MB_JOB_BASE + MB_JOB_STRIDE * MB_JOB_SLOTS_MAX <= MB_SENSOR_BASE,
              "the job slots run into the sensor slots");
static_assert(MB_ADDR_END <= 65536, "the map does not fit 16-bit addresses");
static_assert(MB_S_NAME + MB_NAME_BYTES / 2 == MB_SENSOR_STRIDE,
              "the sensor name is not the last MB_NAME_BYTES bytes");

/* ------------------------------------------------------------- encoders */

static const struct {
	int regs;
	const char *name, *sentinel;
} types[MB_NTYPES] = {
#define TYPE_(name, regs, doc, sentinel) {regs, doc, sentinel},
        MB_TYPES(TYPE_)
#undef TYPE_
};

int mb_type_regs(mb_type t)
{
	return t < MB_NTYPES ? types[t].regs : 0;
}

const char *mb_type_name(mb_type t)
{
	return t < MB_NTYPES ? types[t].name : "?";
}

int mb_word_order_parse(const char *s, mb_word_order *out)
{
	if (strcasecmp(s, "abcd") == 0)
		*out = MB_ABCD;
	else if (strcasecmp(s, "cdab") == 0)
		*out = MB_CDAB;
	else
		return -1;
	return 0;
}

const char *mb_word_order_name(mb_word_order wo)
{
	return wo == MB_CDAB ? "cdab" : "abcd";
}

void mb_put_u32(uint16_t r[2], uint32_t v, mb_word_order wo)
{
	uint16_t hi = (uint16_t)(v >> 16), lo = (uint16_t)(v & 0xFFFF);
	r[0] = wo == MB_CDAB ? lo : hi;
	r[1] = wo == MB_CDAB ? hi : lo;
}

uint32_t mb_get_u32(const uint16_t r[2], mb_word_order wo)
{
	uint32_t hi = wo == MB_CDAB ? r[1] : r[0];
	uint32_t lo = wo == MB_CDAB ? r[0] : r[1];
	return hi << 16 | lo;
}

void mb_put_i32(uint16_t r[2], int32_t v, mb_word_order wo)
{
	uint32_t u;
	memcpy(&u, &v, sizeof u);
	mb_put_u32(r, u, wo);
}

int32_t mb_get_i32(const uint16_t r[2], mb_word_order wo)
{
	uint32_t u = mb_get_u32(r, wo);
	int32_t v;
	memcpy(&v, &u, sizeof v);
	return v;
}

void mb_put_f32(uint16_t r[2], float v, mb_word_order wo)
{
	uint32_t u = 0x7FC00000u; /* one NaN for every NaN */
	if (!isnan(v))
		memcpy(&u, &v, sizeof u);
	mb_put_u32(r, u, wo);
}

float mb_get_f32(const uint16_t r[2], mb_word_order wo)
{
	uint32_t u = mb_get_u32(r, wo);
	float v;
	memcpy(&v, &u, sizeof v);
	return v;
}

void mb_put_str(uint16_t *r, size_t nregs, const char *s)
{
	size_t n = strnlen(s, 2 * nregs);
	for (size_t i = 0; i < nregs; i++) {
		unsigned hi = 2 * i < n ? (unsigned char)s[2 * i] : 0;
		unsigned lo = 2 * i + 1 < n ? (unsigned char)s[2 * i + 1] : 0;
		r[i] = (uint16_t)(hi << 8 | lo);
	}
}

uint16_t mb_u16_of(uint64_t v)
{
	return v >= MB_U16_NA ? (uint16_t)(MB_U16_NA - 1) : (uint16_t)v;
}

uint32_t mb_u32_of(uint64_t v)
{
	return v >= MB_U32_NA ? MB_U32_NA - 1 : (uint32_t)v;
}

uint32_t mb_u32_of_double(double v)
{
	if (isnan(v) || v < 0)
		return MB_U32_NA;
	v = floor(v + 0.5);
	return v >= (double)(MB_U32_NA - 1) ? MB_U32_NA - 1 : (uint32_t)v;
}

uint32_t mb_kib_of_bytes(int64_t bytes)
{
	if (bytes < 0)
		return MB_U32_NA;
	return mb_u32_of(((uint64_t)bytes + 1023) / 1024);
}

uint16_t mb_permille_of(double fraction)
{
	if (isnan(fraction))
		return MB_U16_NA;
	double p = floor(fraction * 1000 + 0.5);
	return p <= 0 ? 0 : p >= 1000 ? 1000 : (uint16_t)p;
}

uint16_t mb_lux_scaled(double lux, double scale)
{
	double v = lux * scale;
	if (isnan(v))
		return MB_U16_NA;
	v = floor(v + 0.5);
	return v <= 0 ? 0 : v >= MB_U16_NA - 1 ? MB_U16_NA - 1 : (uint16_t)v;
}

/* ------------------------------------------------------------- document */

typedef struct field {
	const char *name, *unit, *desc;
	int off, regs;
	mb_type type;
	mb_avail avail;
} field;

#define ROW_(name, off, regs, type, unit, avail, desc)                         \
	{#name, unit, desc, off, regs, MB_##type, MB_##avail},
static const field daemon_fields[] = {MB_DAEMON_MAP(ROW_)};
static const field job_fields[] = {MB_JOB_MAP(ROW_)};
static const field sensor_fields[] = {MB_SENSOR_MAP(ROW_)};
#undef ROW_

#define COUNT(a) (sizeof(a) / sizeof((a)[0]))

/* One table row; slot blocks show the offset and slot 0's address. */
static void write_row(FILE *f, const field *fl, int base, int slotted)
{
	char name[64];
	size_t i;
	for (i = 0; fl->name[i] && i + 1 < sizeof name; i++)
		name[i] = (char)tolower((unsigned char)fl->name[i]);
	name[i] = '\0';
	if (slotted)
		fprintf(f, "| +%d ", fl->off);
	fprintf(f, "| %d | %d | `%s` | %s | %s | %s | %s |\n", base + fl->off,
	        fl->regs, name, types[fl->type].name, fl->unit,
	        fl->avail == MB_ALWAYS ? "—" : types[fl->type].sentinel,
	        fl->desc);
}

static void write_block(FILE *f, const char *title, const field *fl, size_t n,
                        int base, int slotted)
{
	fprintf(f, "### %s\n\n", title);
	if (slotted)
		fprintf(f, "| Offset | Slot 0 | Regs | Name | Type | Unit | "
		           "Sentinel | Description |\n"
		           "|---:|---:|---:|---|---|---|---|---|\n");
	else
		fprintf(f, "| Address | Regs | Name | Type | Unit | Sentinel | "
		           "Description |\n"
		           "|---:|---:|---|---|---|---|---|\n");
	for (size_t i = 0; i < n; i++)
		write_row(f, &fl[i], base, slotted);
	fprintf(f, "\n");
}

int mb_map_write_markdown(FILE *f)
{
	char title[160];
	fprintf(f,
	        "Map version %d.  Input registers (function 0x04), "
	        "0-based addresses.\n\n",
	        MB_MAP_VERSION);
	snprintf(title, sizeof title, "Daemon block: addresses %d..%d",
	         MB_DAEMON_BASE, MB_DAEMON_BASE + MB_DAEMON_REGS - 1);
	write_block(f, title, daemon_fields, COUNT(daemon_fields),
	            MB_DAEMON_BASE, 0);
	snprintf(title, sizeof title,
	         "Job slots: slot k at %d + %d·k, k < job_slots (at most %d)",
	         MB_JOB_BASE, MB_JOB_STRIDE, MB_JOB_SLOTS_MAX);
	write_block(f, title, job_fields, COUNT(job_fields), MB_JOB_BASE, 1);
	snprintf(title, sizeof title,
	         "Sensor slots: slot k at %d + %d·k, k < sensor_slots (at "
	         "most %d)",
	         MB_SENSOR_BASE, MB_SENSOR_STRIDE, MB_SENSOR_SLOTS_MAX);
	write_block(f, title, sensor_fields, COUNT(sensor_fields),
	            MB_SENSOR_BASE, 1);
	fprintf(f,
	        "### Job states (`state`)\n\n| Value | State |\n|---:|---|\n");
#define JS_(name, v, doc) fprintf(f, "| %d | %s |\n", v, doc);
	MB_JOB_STATES(JS_)
#undef JS_
	fprintf(f, "\n### Sensor status (`status`)\n\n| Value | Status "
	           "|\n|---:|---|\n");
#define SS_(name, v, doc) fprintf(f, "| %d | %s |\n", v, doc);
	MB_SENSOR_STATUSES(SS_)
#undef SS_
	return ferror(f) ? -1 : 0;
}
