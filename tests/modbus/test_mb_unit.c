/*
 * test_mb_unit.c -- the Modbus module without a network: the encoders
 * (known bit patterns in both word orders), sentinels, saturation and lux
 * scaling, the config keys, the register image (addresses, empty slots,
 * every field of a published job and sensor), the slot rule, and the
 * server's start / stop / errors.  Real clients are in the scripts.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "modbus.h"

/* ------------------------------------------------------------ encoders */

static void test_u32_word_orders(void **state)
{
	(void)state;
	uint16_t r[2];
	mb_put_u32(r, 0x12345678, MB_ABCD);
	assert_int_equal(r[0], 0x1234);
	assert_int_equal(r[1], 0x5678);
	assert_int_equal(mb_get_u32(r, MB_ABCD), 0x12345678);
	mb_put_u32(r, 0x12345678, MB_CDAB);
	assert_int_equal(r[0], 0x5678);
	assert_int_equal(r[1], 0x1234);
	assert_int_equal(mb_get_u32(r, MB_CDAB), 0x12345678);
	mb_put_i32(r, -2, MB_ABCD);
	assert_int_equal(r[0], 0xFFFF);
	assert_int_equal(r[1], 0xFFFE);
	assert_int_equal(mb_get_i32(r, MB_ABCD), -2);
	mb_put_i32(r, MB_I32_NA, MB_CDAB);
	assert_int_equal(r[0], 0x0000);
	assert_int_equal(r[1], 0x8000);
}

static void test_f32_known_patterns(void **state)
{
	(void)state;
	static const struct {
		float v;
		uint16_t hi, lo;
	} cases[] = {
	        {1.0f, 0x3F80, 0x0000},        {-2.5f, 0xC020, 0x0000},
	        {0.0f, 0x0000, 0x0000},        {-0.0f, 0x8000, 0x0000},
	        {3.14159274f, 0x4049, 0x0FDB}, {123.456f, 0x42F6, 0xE979},
	        {INFINITY, 0x7F80, 0x0000},    {1e-45f, 0x0000, 0x0001},
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		uint16_t r[2];
		mb_put_f32(r, cases[i].v, MB_ABCD);
		assert_int_equal(r[0], cases[i].hi);
		assert_int_equal(r[1], cases[i].lo);
		assert_true(mb_get_f32(r, MB_ABCD) == cases[i].v);
		mb_put_f32(r, cases[i].v, MB_CDAB);
		assert_int_equal(r[0], cases[i].lo);
		assert_int_equal(r[1], cases[i].hi);
		assert_true(mb_get_f32(r, MB_CDAB) == cases[i].v);
	}
	/* every NaN becomes the one documented sentinel */
	uint16_t r[2];
	mb_put_f32(r, -NAN, MB_ABCD);
	assert_int_equal(r[0], 0x7FC0);
	assert_int_equal(r[1], 0x0000);
	assert_true(isnan(mb_get_f32(r, MB_ABCD)));
}

static void test_string_registers(void **state)
{
	(void)state;
	uint16_t r[8];
	memset(r, 0xAA, sizeof r);
	mb_put_str(r, 8, "desk");
	assert_int_equal(r[0], 0x6465); /* 'd' 'e' */
	assert_int_equal(r[1], 0x736B); /* 's' 'k' */
	for (int i = 2; i < 8; i++)
		assert_int_equal(r[i], 0);
	mb_put_str(r, 8, "odd");
	assert_int_equal(r[1], 0x6400);           /* 'd' then padding */
	mb_put_str(r, 8, "0123456789abcdefTAIL"); /* first 16 bytes only */
	assert_int_equal(r[7], 0x6566);
}

static void test_saturation_and_sentinels(void **state)
{
	(void)state;
	assert_int_equal(mb_u16_of(0), 0);
	assert_int_equal(mb_u16_of(65534), 65534);
	assert_int_equal(mb_u16_of(65535), 65534);
	assert_int_equal(mb_u16_of(1u << 20), 65534);
	assert_int_equal(mb_u32_of(0xFFFFFFFEull), 0xFFFFFFFEu);
	assert_int_equal(mb_u32_of(0xFFFFFFFFull), 0xFFFFFFFEu);
	assert_int_equal(mb_u32_of(1ull << 40), 0xFFFFFFFEu);
	assert_int_equal(mb_u32_of_double(NAN), MB_U32_NA);
	assert_int_equal(mb_u32_of_double(-0.5), MB_U32_NA);
	assert_int_equal(mb_u32_of_double(0.49), 0);
	assert_int_equal(mb_u32_of_double(0.5), 1);
	assert_int_equal(mb_u32_of_double(4e9), 4000000000u);
	assert_int_equal(mb_u32_of_double(1e12), 0xFFFFFFFEu);
	assert_int_equal(mb_u32_of_double(INFINITY), 0xFFFFFFFEu);
	assert_int_equal(mb_kib_of_bytes(-1), MB_U32_NA);
	assert_int_equal(mb_kib_of_bytes(0), 0);
	assert_int_equal(mb_kib_of_bytes(1), 1);
	assert_int_equal(mb_kib_of_bytes(1024), 1);
	assert_int_equal(mb_kib_of_bytes(1025), 2);
	assert_int_equal(mb_kib_of_bytes(INT64_MAX), 0xFFFFFFFEu);
	assert_int_equal(mb_permille_of(NAN), MB_U16_NA);
	assert_int_equal(mb_permille_of(-0.1), 0);
	assert_int_equal(mb_permille_of(0.0004), 0);
	assert_int_equal(mb_permille_of(0.0006), 1);
	assert_int_equal(mb_permille_of(0.5), 500);
	assert_int_equal(mb_permille_of(1.0), 1000);
	assert_int_equal(mb_permille_of(7.0), 1000);
}

static void test_lux_scaling(void **state)
{
	(void)state;
	assert_int_equal(mb_lux_scaled(NAN, 1), MB_U16_NA);
	assert_int_equal(mb_lux_scaled(-5, 1), 0);
	assert_int_equal(mb_lux_scaled(0.49, 1), 0);
	assert_int_equal(mb_lux_scaled(0.5, 1), 1);
	assert_int_equal(mb_lux_scaled(123.456, 1), 123);
	assert_int_equal(mb_lux_scaled(65533.4, 1), 65533);
	assert_int_equal(mb_lux_scaled(65533.6, 1), 65534);
	assert_int_equal(mb_lux_scaled(70000.25, 1), 65534);
	assert_int_equal(mb_lux_scaled(INFINITY, 1), 65534);
	assert_int_equal(mb_lux_scaled(12.34, 10), 123);
	assert_int_equal(mb_lux_scaled(6553.4, 10), 65534);
	assert_int_equal(mb_lux_scaled(6553.5, 10), 65534);
	assert_int_equal(mb_lux_scaled(123456, 0.01), 1235);
}

/* -------------------------------------------------------------- config */

static void test_config_defaults(void **state)
{
	(void)state;
	mb_config c;
	mb_config_default(&c);
	assert_string_equal(c.listen, "127.0.0.1:1502");
	assert_int_equal(c.unit_id, 1);
	assert_int_equal(c.word_order, MB_ABCD);
	assert_int_equal(c.max_clients, 16);
	assert_int_equal(c.job_slots, 8);
	assert_int_equal(c.sensor_slots, 32);
	assert_true(c.lux_scale == 1.0);
	assert_true(c.idle_timeout_s == 60);
	assert_true(c.frame_timeout_s == 2);
	/* every documented default parses, and reads back the same */
	size_t n;
	const mb_config_key *k = mb_config_keys(&n);
	assert_int_equal(n, 9);
	for (size_t i = 0; i < n; i++) {
		char msg[256] = "", a[320], b[320];
		mb_config d = c;
		assert_int_equal(mb_config_set(&d, k[i].name,
		                               k[i].default_value, msg,
		                               sizeof msg),
		                 0);
		assert_true(mb_config_is_key(k[i].name));
		assert_int_equal(mb_config_get(&c, k[i].name, a, sizeof a), 0);
		assert_int_equal(
		        mb_config_set(&d, k[i].name, a, msg, sizeof msg), 0);
		assert_int_equal(mb_config_get(&d, k[i].name, b, sizeof b), 0);
		assert_string_equal(a, b);
	}
}

static void test_config_values(void **state)
{
	(void)state;
	mb_config c;
	char msg[256], v[64];
	mb_config_default(&c);
	assert_int_equal(mb_config_set(&c, "modbus_listen", "none", msg, 256),
	                 0);
	assert_string_equal(c.listen, "");
	assert_int_equal(mb_config_get(&c, "modbus_listen", v, sizeof v), 0);
	assert_string_equal(v, "none");
	assert_int_equal(
	        mb_config_set(&c, "modbus_listen", "[::1]:502", msg, 256), 0);
	assert_string_equal(c.listen, "[::1]:502");
	assert_int_equal(
	        mb_config_set(&c, "modbus_word_order", "CDAB", msg, 256), 0);
	assert_int_equal(c.word_order, MB_CDAB);
	assert_int_equal(
	        mb_config_set(&c, "modbus_idle_timeout", "5m", msg, 256), 0);
	assert_true(c.idle_timeout_s == 300);
	assert_int_equal(
	        mb_config_set(&c, "modbus_frame_timeout", "250ms", msg, 256),
	        0);
	assert_true(c.frame_timeout_s == 0.25);
	assert_int_equal(mb_config_set(&c, "modbus_lux_scale", "0.1", msg, 256),
	                 0);
	assert_int_equal(mb_config_get(&c, "modbus_lux_scale", v, sizeof v), 0);
	assert_string_equal(v, "0.1");
	static const char *const bad[][2] = {
	        {"modbus_listen", "1502"},       {"modbus_listen", "h:70000"},
	        {"modbus_listen", ":1502"},      {"modbus_listen", "[::1]1502"},
	        {"modbus_unit_id", "0"},         {"modbus_unit_id", "248"},
	        {"modbus_unit_id", "1x"},        {"modbus_word_order", "badc"},
	        {"modbus_max_clients", "0"},     {"modbus_job_slots", "65"},
	        {"modbus_sensor_slots", "1025"}, {"modbus_sensor_slots", "-1"},
	        {"modbus_lux_scale", "0"},       {"modbus_lux_scale", "nan"},
	        {"modbus_lux_scale", "1e7"},     {"modbus_idle_timeout", "-1"},
	        {"modbus_idle_timeout", "5 d"},  {"modbus_frame_timeout", "0"},
	        {"modbus_frame_timeout", "2h"},  {"modbus_nonsense", "1"},
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		mb_config before = c;
		msg[0] = '\0';
		assert_int_equal(mb_config_set(&c, bad[i][0], bad[i][1], msg,
		                               sizeof msg),
		                 -1);
		assert_non_null(strstr(msg, bad[i][0])); /* names the key */
		assert_memory_equal(&before, &c, sizeof c);
	}
	assert_int_equal(
	        mb_config_set(&c, "modbus_sensor_slots", "0", msg, 256), 0);
	assert_false(mb_config_is_key("listen_tcp"));
}

/* --------------------------------------------------------------- image */

/* A server with modbus_listen off: the image without a network. */
static mb_server *offline(const char *order, int jobs, int sensors,
                          double scale)
{
	mb_config c;
	char msg[256], n[32];
	mb_config_default(&c);
	assert_int_equal(mb_config_set(&c, "modbus_listen", "none", msg, 256),
	                 0);
	assert_int_equal(
	        mb_config_set(&c, "modbus_word_order", order, msg, 256), 0);
	snprintf(n, sizeof n, "%d", jobs);
	assert_int_equal(mb_config_set(&c, "modbus_job_slots", n, msg, 256), 0);
	snprintf(n, sizeof n, "%d", sensors);
	assert_int_equal(mb_config_set(&c, "modbus_sensor_slots", n, msg, 256),
	                 0);
	snprintf(n, sizeof n, "%g", scale);
	assert_int_equal(mb_config_set(&c, "modbus_lux_scale", n, msg, 256), 0);
	mb_server *s = mb_server_start(&c, NULL, NULL, msg, sizeof msg);
	assert_non_null(s);
	mb_stats st;
	mb_server_stats(s, &st);
	assert_int_equal(st.state, MB_STATE_OFF);
	assert_int_equal(mb_server_port(s), -1);
	return s;
}

static uint16_t reg(mb_server *s, unsigned addr)
{
	uint16_t v;
	assert_int_equal(mb_server_read(s, addr, 1, &v), 0);
	return v;
}

static uint32_t reg32(mb_server *s, unsigned addr, mb_word_order wo)
{
	uint16_t r[2];
	assert_int_equal(mb_server_read(s, addr, 2, r), 0);
	return mb_get_u32(r, wo);
}

static float regf(mb_server *s, unsigned addr, mb_word_order wo)
{
	uint16_t r[2];
	assert_int_equal(mb_server_read(s, addr, 2, r), 0);
	return mb_get_f32(r, wo);
}

static void test_served_addresses(void **state)
{
	(void)state;
	mb_server *s = offline("abcd", 8, 32, 1);
	uint16_t r[125];
	static const struct {
		unsigned addr, n;
		int exc;
	} cases[] = {
	        {0, 21, 0},     {0, 22, 2},   {20, 1, 0},      {20, 2, 2},
	        {21, 1, 2},     {999, 1, 2},  {999, 2, 2},     {1000, 125, 0},
	        {1159, 1, 0},   {1159, 2, 2}, {1160, 1, 2},    {2999, 1, 2},
	        {3000, 125, 0}, {3511, 1, 0}, {3512, 1, 2},    {65535, 1, 2},
	        {0, 0, 3},      {0, 126, 3},  {65535, 126, 3}, {1000, 126, 3},
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
		assert_int_equal(
		        mb_server_read(s, cases[i].addr, cases[i].n, r),
		        cases[i].exc);
	mb_server_stop(s);
	s = offline("abcd", 1, 0, 1);
	assert_int_equal(mb_server_read(s, 1000, 20, r), 0);
	assert_int_equal(mb_server_read(s, 1020, 1, r), 2);
	assert_int_equal(mb_server_read(s, 3000, 1, r), 2);
	mb_server_stop(s);
}

static void test_daemon_block(void **state)
{
	(void)state;
	mb_server *s = offline("cdab", 5, 7, 10);
	assert_int_equal(reg(s, MB_D_MAP_VERSION), MB_MAP_VERSION);
	assert_int_equal(reg(s, MB_D_JOB_SLOTS), 5);
	assert_int_equal(reg(s, MB_D_SENSOR_SLOTS), 7);
	assert_int_equal(reg(s, MB_D_WORD_ORDER), 1);
	assert_int_equal(reg(s, MB_D_FLOAT_PROBE), 0x0000); /* CDAB */
	assert_int_equal(reg(s, MB_D_FLOAT_PROBE + 1), 0x3F80);
	assert_true(regf(s, MB_D_LUX_SCALE, MB_CDAB) == 10.0f);
	assert_int_equal(reg32(s, MB_D_UPTIME, MB_CDAB), MB_U32_NA);
	assert_int_equal(reg32(s, MB_D_MEMORY, MB_CDAB), MB_U32_NA);
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	mb_daemon_vals d = {(double)ts.tv_sec - 100, 2048};
	mb_publish_daemon(s, &d);
	uint32_t up = reg32(s, MB_D_UPTIME, MB_CDAB);
	assert_true(up >= 100 && up <= 102);
	assert_int_equal(reg32(s, MB_D_MEMORY, MB_CDAB), 2);
	for (unsigned a = MB_D_JOBS_QUEUED; a <= MB_D_MODBUS_CLIENTS; a++)
		if (a != MB_D_MEMORY && a != MB_D_MEMORY + 1)
			assert_int_equal(reg(s, a), 0);
	mb_server_stop(s);
}

static void test_empty_slots(void **state)
{
	(void)state;
	mb_server *s = offline("abcd", 2, 2, 1);
	uint16_t j[MB_JOB_STRIDE], e[MB_JOB_STRIDE];
	assert_int_equal(mb_server_read(s, MB_JOB_BASE + MB_JOB_STRIDE, 20, j),
	                 0);
	for (unsigned i = 0; i < MB_JOB_STRIDE; i++)
		e[i] = 0xFFFF;
	e[MB_J_JOB_ID] = e[MB_J_JOB_ID + 1] = e[MB_J_STATE] = 0;
	e[MB_J_RESIDUAL] = e[MB_J_ERROR_ESTIMATE] = 0x7FC0;
	e[MB_J_RESIDUAL + 1] = e[MB_J_ERROR_ESTIMATE + 1] = 0;
	assert_memory_equal(j, e, sizeof e);
	uint16_t r[MB_SENSOR_STRIDE];
	assert_int_equal(mb_server_read(s, MB_SENSOR_BASE, 16, r), 0);
	assert_int_equal(mb_get_u32(r + MB_S_JOB_ID, MB_ABCD), 0);
	assert_true(isnan(mb_get_f32(r + MB_S_LUX, MB_ABCD)));
	assert_int_equal(mb_get_u32(r + MB_S_ITERATION, MB_ABCD), MB_U32_NA);
	assert_int_equal(r[MB_S_STATUS], MB_SENSOR_EMPTY);
	assert_int_equal(r[MB_S_LUX_SCALED], MB_U16_NA);
	for (int i = 0; i < 8; i++)
		assert_int_equal(r[MB_S_NAME + i], 0);
	mb_server_stop(s);
}

static void test_job_fields(void **state)
{
	(void)state;
	for (int o = 0; o < 2; o++) {
		mb_word_order wo = o ? MB_CDAB : MB_ABCD;
		mb_server *s = offline(o ? "cdab" : "abcd", 8, 4, 1);
		mb_job_vals v;
		mb_job_vals_init(&v, 77);
		v.scene_id = 5;
		v.state = MB_JOB_RUNNING;
		v.iteration = 70000;
		v.progress = 0.4567;
		v.residual = 0.125;
		v.error_estimate = 1e-3;
		v.links = 5000000000LL; /* clipped */
		v.memory_bytes = 3 << 20;
		v.elapsed_s = 12.4;
		v.eta_s = 99.5;
		assert_int_equal(mb_publish_job(s, &v), 0);
		const unsigned b = MB_JOB_BASE;
		assert_int_equal(reg32(s, b + MB_J_JOB_ID, wo), 77);
		assert_int_equal(reg(s, b + MB_J_STATE), MB_JOB_RUNNING);
		assert_int_equal(reg(s, b + MB_J_PROGRESS), 457);
		assert_int_equal(reg32(s, b + MB_J_ITERATION, wo), 70000);
		assert_true(regf(s, b + MB_J_RESIDUAL, wo) == 0.125f);
		assert_true(regf(s, b + MB_J_ERROR_ESTIMATE, wo) == 1e-3f);
		assert_int_equal(reg32(s, b + MB_J_LINKS, wo), 0xFFFFFFFEu);
		assert_int_equal(reg32(s, b + MB_J_MEMORY, wo), 3072);
		assert_int_equal(reg32(s, b + MB_J_ELAPSED, wo), 12);
		assert_int_equal(reg32(s, b + MB_J_ETA, wo), 100);
		assert_int_equal(reg32(s, b + MB_J_SCENE_ID, wo), 5);
		assert_int_equal(reg(s, MB_D_JOBS_RUNNING), 1);
		v.state = MB_JOB_FAILED; /* a state change moves the count */
		mb_publish_job(s, &v);
		assert_int_equal(reg(s, MB_D_JOBS_RUNNING), 0);
		assert_int_equal(reg(s, MB_D_JOBS_FAILED), 1);
		mb_job_vals_init(&v, 0);
		assert_int_equal(mb_publish_job(s, &v), -2);
		mb_job_vals_init(&v, 5);
		v.state = MB_JOB_EMPTY;
		assert_int_equal(mb_publish_job(s, &v), -2);
		v.state = MB_JOB_NSTATES;
		assert_int_equal(mb_publish_job(s, &v), -2);
		mb_job_vals_init(&v,
		                 1ull << 40); /* id does not fit: sentinel */
		assert_int_equal(mb_publish_job(s, &v), 1);
		assert_int_equal(reg32(s, b + MB_JOB_STRIDE, wo), MB_U32_NA);
		mb_server_stop(s);
	}
}

static void publish_state(mb_server *s, uint64_t id, mb_job_state st,
                          int64_t it, int want_slot)
{
	mb_job_vals v;
	mb_job_vals_init(&v, id);
	v.state = st;
	v.iteration = it;
	assert_int_equal(mb_publish_job(s, &v), want_slot);
}

static void test_job_slot_rule(void **state)
{
	(void)state;
	mb_server *s = offline("abcd", 2, 4, 1);
	const unsigned slot1 = MB_JOB_BASE + MB_JOB_STRIDE;
	publish_state(s, 5, MB_JOB_RUNNING, 1, 0);
	publish_state(s, 7, MB_JOB_QUEUED, 0, 1);
	publish_state(s, 9, MB_JOB_PAUSED, 3, -1); /* full: unslotted */
	publish_state(s, 11, MB_JOB_DONE, 8, -1);
	assert_int_equal(reg(s, MB_D_JOBS_UNSLOTTED), 2);
	publish_state(s, 9, MB_JOB_DONE, 42, -1); /* values kept unslotted */
	assert_int_equal(reg(s, MB_D_JOBS_DONE), 2);
	assert_int_equal(reg(s, MB_D_JOBS_PAUSED), 0);
	publish_state(s, 5, MB_JOB_RUNNING, 2, 0); /* keeps its slot */
	mb_job_remove(s, 5);                       /* 9 (lowest id) moves in */
	assert_int_equal(mb_job_slot(s, 9), 0);
	assert_int_equal(reg32(s, MB_JOB_BASE, MB_ABCD), 9);
	assert_int_equal(reg(s, MB_JOB_BASE + MB_J_STATE), MB_JOB_DONE);
	assert_int_equal(reg32(s, MB_JOB_BASE + MB_J_ITERATION, MB_ABCD), 42);
	assert_int_equal(mb_job_slot(s, 7), 1); /* untouched */
	assert_int_equal(reg(s, MB_D_JOBS_UNSLOTTED), 1);
	assert_int_equal(reg(s, MB_D_JOBS_RUNNING), 0);
	mb_job_remove(s, 1234); /* unknown: nothing happens */
	mb_job_remove(s, 11);   /* unslotted one leaves */
	assert_int_equal(reg(s, MB_D_JOBS_UNSLOTTED), 0);
	mb_job_remove(s, 7);
	assert_int_equal(reg32(s, slot1, MB_ABCD), 0); /* empty again */
	assert_int_equal(reg(s, slot1 + MB_J_STATE), MB_JOB_EMPTY);
	assert_int_equal(reg32(s, slot1 + MB_J_ITERATION, MB_ABCD), MB_U32_NA);
	publish_state(s, 20, MB_JOB_QUEUED, 0, 1); /* lowest free slot */
	assert_int_equal(mb_job_slot(s, 20), 1);
	assert_int_equal(mb_job_slot(s, 5), -1);
	mb_server_stop(s);
}

static void test_sensor_fields_and_slots(void **state)
{
	(void)state;
	mb_server *s = offline("abcd", 4, 2, 10);
	const unsigned b0 = MB_SENSOR_BASE, b1 = b0 + MB_SENSOR_STRIDE;
	assert_int_equal(mb_publish_sensor(s, 3, "desk", NAN, 0), 0);
	assert_int_equal(reg(s, b0 + MB_S_STATUS), MB_SENSOR_WAITING);
	assert_int_equal(reg32(s, b0 + MB_S_JOB_ID, MB_ABCD), 3);
	assert_true(isnan(regf(s, b0 + MB_S_LUX, MB_ABCD)));
	assert_int_equal(reg(s, b0 + MB_S_LUX_SCALED), MB_U16_NA);
	assert_int_equal(reg32(s, b0 + MB_S_ITERATION, MB_ABCD), MB_U32_NA);
	assert_int_equal(reg(s, b0 + MB_S_NAME), 0x6465);
	assert_int_equal(mb_publish_sensor(s, 3, "desk", 250.56, 4), 0);
	assert_int_equal(reg(s, b0 + MB_S_STATUS), MB_SENSOR_VALID);
	assert_true(regf(s, b0 + MB_S_LUX, MB_ABCD) == 250.56f);
	assert_int_equal(reg(s, b0 + MB_S_LUX_SCALED), 2506); /* scale 10 */
	assert_int_equal(reg32(s, b0 + MB_S_ITERATION, MB_ABCD), 4);
	assert_int_equal(mb_publish_sensor(s, 4, "a", 1, 1), 1);
	assert_int_equal(mb_publish_sensor(s, 3, "zz", 2, 1), -1);
	assert_int_equal(mb_publish_sensor(s, 3, "b", 3, 1), -1);
	assert_int_equal(reg(s, MB_D_SENSORS_UNSLOTTED), 2);
	/* refused */
	char longname[MB_SENSOR_NAME_MAX + 1];
	memset(longname, 'x', MB_SENSOR_NAME_MAX);
	longname[MB_SENSOR_NAME_MAX] = '\0';
	assert_int_equal(mb_publish_sensor(s, 3, longname, 1, 1), -2);
	assert_int_equal(mb_publish_sensor(s, 3, "", 1, 1), -2);
	assert_int_equal(mb_publish_sensor(s, 0, "x", 1, 1), -2);
	/* removing job 4 frees slot 1: (3, "b") is first in key order */
	mb_job_remove(s, 4);
	assert_int_equal(mb_sensor_slot(s, 3, "b"), 1);
	assert_int_equal(reg(s, b1 + MB_S_NAME), 0x6200);
	assert_true(regf(s, b1 + MB_S_LUX, MB_ABCD) == 3.0f);
	assert_int_equal(mb_sensor_slot(s, 3, "zz"), -1);
	mb_sensor_remove(s, 3, "desk");
	assert_int_equal(mb_sensor_slot(s, 3, "zz"), 0);
	assert_int_equal(reg(s, MB_D_SENSORS_UNSLOTTED), 0);
	mb_job_remove(s, 3); /* a job's sensors go with it */
	assert_int_equal(reg(s, b0 + MB_S_STATUS), MB_SENSOR_EMPTY);
	assert_int_equal(reg(s, b1 + MB_S_STATUS), MB_SENSOR_EMPTY);
	assert_int_equal(reg32(s, b1 + MB_S_JOB_ID, MB_ABCD), 0);
	assert_int_equal(reg(s, b1 + MB_S_NAME), 0);
	mb_server_stop(s);
}

static void test_null_server_is_harmless(void **state)
{
	(void)state;
	mb_job_vals v;
	mb_job_vals_init(&v, 1);
	mb_daemon_vals d = {0, 0};
	mb_publish_daemon(NULL, &d);
	assert_int_equal(mb_publish_job(NULL, &v), -2);
	assert_int_equal(mb_publish_sensor(NULL, 1, "a", 1, 1), -2);
	mb_job_remove(NULL, 1);
	mb_sensor_remove(NULL, 1, "a");
	assert_int_equal(mb_job_slot(NULL, 1), -1);
	mb_stats st;
	mb_server_stats(NULL, &st);
	assert_int_equal(st.port, -1);
	mb_server_stop(NULL);
}

/* -------------------------------------------------------------- server */

static void test_start_stop_and_errors(void **state)
{
	(void)state;
	mb_config c;
	char msg[256];
	mb_config_default(&c);
	mb_config_set(&c, "modbus_listen", "127.0.0.1:0", msg, sizeof msg);
	mb_server *s = mb_server_start(&c, NULL, NULL, msg, sizeof msg);
	assert_non_null(s);
	int port = mb_server_port(s);
	assert_true(port > 0);
	mb_stats st;
	mb_server_stats(s, &st);
	assert_int_equal(st.state, MB_STATE_LISTENING);
	assert_int_equal(st.port, port);
	assert_string_equal(mb_state_name(st.state), "listening");
	/* the same port again: refused with the system's reason */
	mb_config c2 = c;
	snprintf(c2.listen, sizeof c2.listen, "127.0.0.1:%d", port);
	msg[0] = '\0';
	assert_null(mb_server_start(&c2, NULL, NULL, msg, sizeof msg));
	assert_non_null(strstr(msg, "in use"));
	snprintf(c2.listen, sizeof c2.listen, "no.such.host.invalid:0");
	assert_null(mb_server_start(&c2, NULL, NULL, msg, sizeof msg));
	assert_non_null(strstr(msg, "no.such.host.invalid"));
	snprintf(c2.listen, sizeof c2.listen, "bad");
	assert_null(mb_server_start(&c2, NULL, NULL, msg, sizeof msg));
	mb_server_stop(s);
}

static void test_markdown_mentions_every_block(void **state)
{
	(void)state;
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	assert_non_null(f);
	assert_int_equal(mb_map_write_markdown(f), 0);
	fclose(f);
	assert_non_null(strstr(buf, "| 0 | 1 | `map_version` | u16 |"));
	assert_non_null(strstr(buf, "| +4 | 1004 | 2 | `iteration` | u32 |"));
	assert_non_null(
	        strstr(buf, "| +2 | 3002 | 2 | `lux` | f32 | lx | NaN"));
	assert_non_null(strstr(buf, "| 6 | cancelled |"));
	free(buf);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_u32_word_orders),
	        cmocka_unit_test(test_f32_known_patterns),
	        cmocka_unit_test(test_string_registers),
	        cmocka_unit_test(test_saturation_and_sentinels),
	        cmocka_unit_test(test_lux_scaling),
	        cmocka_unit_test(test_config_defaults),
	        cmocka_unit_test(test_config_values),
	        cmocka_unit_test(test_served_addresses),
	        cmocka_unit_test(test_daemon_block),
	        cmocka_unit_test(test_empty_slots),
	        cmocka_unit_test(test_job_fields),
	        cmocka_unit_test(test_job_slot_rule),
	        cmocka_unit_test(test_sensor_fields_and_slots),
	        cmocka_unit_test(test_null_server_is_harmless),
	        cmocka_unit_test(test_start_stop_and_errors),
	        cmocka_unit_test(test_markdown_mentions_every_block),
	};
	if (getenv("LUXRAD_TEST_FILTER"))
		cmocka_set_test_filter(getenv("LUXRAD_TEST_FILTER"));
	return cmocka_run_group_tests(tests, NULL, NULL);
}
