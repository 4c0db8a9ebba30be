/*
 * mb_tornread.c -- the torn-read check: a libmodbus client reads, over
 * and over, three 32-bit values that mb_testserver --mode torn flips
 * between two patterns whose words both differ (job slot 0's iteration
 * 0x0000FFFF / 0x00010000, its residual and sensor slot 0's lux 1.0f /
 * 0x40490FDB).  A pair made of one word of each is a torn update.
 *
 *   mb_tornread PORT READS [abcd|cdab]
 *
 * Exit 0 when every pair read was whole and both patterns of each value
 * were seen (else the check proved nothing), 1 otherwise.
 */
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <modbus/modbus.h>

typedef struct value {
	const char *name;
	uint32_t a, b; /* the two patterns */
	unsigned long seen[2], torn;
} value;

/* Classify the pair at r[0..1] (word order cdab?) into v. */
static void classify(value *v, const uint16_t *r, int cdab)
{
	uint32_t hi = cdab ? r[1] : r[0], lo = cdab ? r[0] : r[1];
	uint32_t x = hi << 16 | lo;
	if (x == v->a)
		v->seen[0]++;
	else if (x == v->b)
		v->seen[1]++;
	else if (v->torn++ < 5)
		fprintf(stderr, "mb_tornread: %s torn: 0x%08x\n", v->name, x);
}

int main(int argc, char **argv)
{
	if (argc < 3) {
		fprintf(stderr, "usage: mb_tornread PORT READS [abcd|cdab]\n");
		return 2;
	}
	long reads = atol(argv[2]);
	int cdab = argc > 3 && strcmp(argv[3], "cdab") == 0;
	modbus_t *ctx = modbus_new_tcp("127.0.0.1", atoi(argv[1]));
	if (!ctx || modbus_connect(ctx) < 0) {
		fprintf(stderr, "mb_tornread: connect: %s\n",
		        modbus_strerror(errno));
		return 1;
	}
	modbus_set_response_timeout(ctx, 2, 0);
	value it = {"iteration", 0x0000FFFF, 0x00010000, {0, 0}, 0};
	value res = {"residual", 0x3F800000, 0x40490FDB, {0, 0}, 0};
	value lux = {"sensor lux", 0x3F800000, 0x40490FDB, {0, 0}, 0};
	for (long k = 0; k < reads; k++) {
		uint16_t r[4];
		if (modbus_read_input_registers(ctx, 1004, 4, r) != 4) {
			fprintf(stderr, "mb_tornread: read 1004: %s\n",
			        modbus_strerror(errno));
			return 1;
		}
		classify(&it, r, cdab);
		classify(&res, r + 2, cdab);
		if (modbus_read_input_registers(ctx, 3002, 2, r) != 2) {
			fprintf(stderr, "mb_tornread: read 3002: %s\n",
			        modbus_strerror(errno));
			return 1;
		}
		classify(&lux, r, cdab);
	}
	modbus_close(ctx);
	modbus_free(ctx);
	int ok = 1;
	const value *all[] = {&it, &res, &lux};
	for (int i = 0; i < 3; i++) {
		const value *v = all[i];
		printf("%s: %lu + %lu whole, %lu torn\n", v->name, v->seen[0],
		       v->seen[1], v->torn);
		if (v->torn || !v->seen[0] || !v->seen[1])
			ok = 0;
	}
	return ok ? 0 : 1;
}
