/*
 * cmd_sensors.c -- luxrad sensor-add and luxrad sensors: the named points
 * whose illuminance the daemon publishes over Modbus after every
 * iteration (protocol sensor.add / sensor.list).
 */
#include <stdio.h>

#include "client.h"

int lx_cmd_sensor_add(lx_ctx *cx)
{
	long long job;
	double at[3], n[3] = {0, 1, 0};
	json_t *reply = NULL;
	int rc;

	if (lx_pos_id(cx, 0, "job", &job) != 0)
		return LX_EXIT_USAGE;
	if (!cx->given[LX_OPT_AT])
		return lx_usage_error(cx, "give the sensor's position: --at "
		                          "X,Y,Z");
	if (lx_opt_vec3(cx, LX_OPT_AT, at) ||
	    (cx->given[LX_OPT_NORMAL] && lx_opt_vec3(cx, LX_OPT_NORMAL, n)))
		return LX_EXIT_USAGE;
	if (n[0] == 0 && n[1] == 0 && n[2] == 0)
		return lx_usage_error(cx, "--normal: must not be zero");
	json_t *name = json_string(cx->pos[1]);
	if (!name)
		return lx_usage_error(cx, "NAME must be UTF-8 text");
	json_t *req = lx_req_id(RP_CMD_SENSOR_ADD, "job", job);
	json_object_set_new(req, "name", name);
	json_object_set_new(
	        req, "point",
	        json_pack("[ffffff]", at[0], at[1], at[2], n[0], n[1], n[2]));
	rc = lx_simple_call(cx, req, &reply);
	if (rc == LX_EXIT_OK && !cx->json) {
		json_t *slot = json_object_get(reply, "slot");
		printf("job %lld: sensor '%s' added", job,
		       lx_jstr(reply, "name"));
		if (json_is_integer(slot))
			printf(", Modbus slot %lld\n", lx_jint(reply, "slot"));
		else
			printf(", no free Modbus slot yet\n");
	}
	json_decref(reply);
	return rc;
}

int lx_cmd_sensors(lx_ctx *cx)
{
	long long job;
	json_t *reply = NULL;
	int rc;

	if (lx_pos_id(cx, 0, "job", &job) != 0)
		return LX_EXIT_USAGE;
	rc = lx_simple_call(cx, lx_req_id(RP_CMD_SENSOR_LIST, "job", job),
	                    &reply);
	if (rc != LX_EXIT_OK || cx->json) {
		json_decref(reply);
		return rc;
	}
	json_t *arr = json_object_get(reply, "sensors");
	if (json_array_size(arr) == 0)
		printf("job %lld has no sensors\n", job);
	else
		printf("%-20s %-6s %5s %12s %9s  %s\n", "name", "source",
		       "slot", "lux", "iteration", "point (x y z nx ny nz)");
	for (size_t i = 0; i < json_array_size(arr); i++) {
		json_t *s = json_array_get(arr, i), *p;
		char lux[32], slot[32], it[32];
		printf("%-20s %-6s %5s %12s %9s ", lx_jstr(s, "name"),
		       lx_jstr(s, "source"),
		       lx_jnum(s, "slot", "%.0f", slot, sizeof(slot)),
		       lx_jnum(s, "lux", "%.6g", lux, sizeof(lux)),
		       lx_jnum(s, "iteration", "%.0f", it, sizeof(it)));
		p = json_object_get(s, "point");
		for (size_t k = 0; k < json_array_size(p); k++)
			printf(" %g", json_number_value(json_array_get(p, k)));
		printf("\n");
	}
	json_decref(reply);
	return rc;
}
