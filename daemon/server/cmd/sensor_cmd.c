/*
 * sensor_cmd.c -- sensor.add and sensor.list: a job's sensors (those of
 * its scene, then those added here), their latest lux and their Modbus
 * slots.  The sensors themselves are kept and evaluated by the Modbus
 * glue (mb_glue.c); an added sensor is recorded in the store so that a
 * restart brings it back.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "engine_json.h"
#include "log.h"
#include "modbus.h"

static json_t *sensor_json(cmd_server *d, uint64_t job, const cmd_sensor *x)
{
	json_t *o = json_object(), *pt = json_array();
	for (int k = 0; k < 6; k++)
		json_array_append_new(pt, json_real(x->pt[k]));
	json_object_set_new(o, "name", json_string(x->name));
	json_object_set_new(o, "point", pt);
	json_object_set_new(o, "source",
	                    json_string(x->added ? "added" : "scene"));
	json_object_set_new(o, "lux", ej_real(x->lux));
	json_object_set_new(o, "iteration",
	                    x->iter >= 0 ? json_integer(x->iter) : json_null());
	int slot = cmd_mb_sensor_slot(d, job, x->name);
	json_object_set_new(o, "slot",
	                    slot >= 0 ? json_integer(slot) : json_null());
	return o;
}

/* ------------------------------------------------ sensors in the store */

typedef struct sensor_task {
	srv_task t;
	uint64_t job;
	char name[MB_SENSOR_NAME_MAX];
	double pt[6];
	json_t *reply;
} sensor_task;

static void sensor_run(srv *s, srv_task *t)
{
	sensor_task *k = (sensor_task *)t;
	char msg[512];
	pthread_mutex_lock(&s->store_mu);
	int rc = srv_store_sensor_add(s->store, k->job, k->name, k->pt, msg,
	                              sizeof(msg));
	pthread_mutex_unlock(&s->store_mu);
	if (rc != 0) {
		srv_error("job %llu: cannot record sensor '%s': %s",
		          (unsigned long long)k->job, k->name, msg);
		json_decref(k->reply);
		k->reply = rp_reply_error(t->id, RP_ERR_IO,
		                          "the sensor was added but could not "
		                          "be recorded (a restart will forget "
		                          "it): %s",
		                          msg);
	}
}

static void sensor_done(srv *s, srv_task *t)
{
	sensor_task *k = (sensor_task *)t;
	cmd_task_reply(s, t, k->reply);
}

/* Write the sensor's row on the store thread, then send reply. */
static cmd_result record_sensor(cmd_req *r, uint64_t job, const char *name,
                                const double pt[6], json_t *reply)
{
	sensor_task *k = calloc(1, sizeof(*k));
	if (!k || !reply) {
		free(k);
		json_decref(reply);
		return cmd_req_fail(r, RP_ERR_NOMEM,
		                    "out of memory (the sensor was added but "
		                    "is not recorded)");
	}
	k->job = job;
	snprintf(k->name, sizeof(k->name), "%s", name);
	memcpy(k->pt, pt, sizeof(k->pt));
	k->reply = reply;
	return cmd_req_defer(r, &r->s->store_pool, &k->t, sensor_run,
	                     sensor_done);
}

cmd_result cmd_sensor_add(cmd_req *r)
{
	int failed;
	const char *name;
	double pt[6];
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return CMD_ERROR;
	if (rp_arg_string(r->hdr, "name", 1, &name, &r->err) != 0 ||
	    rp_arg_vec(r->hdr, "point", 1, pt, 6, &r->err) != 0)
		return CMD_ERROR;
	size_t nl = strlen(name);
	if (nl == 0 || nl >= MB_SENSOR_NAME_MAX)
		return cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		                    "\"name\" must be 1..%d bytes",
		                    MB_SENSOR_NAME_MAX - 1);
	for (size_t i = 0; i < nl; i++)
		if ((unsigned char)name[i] < 0x20 || name[i] == 0x7f)
			return cmd_req_fail(r, RP_ERR_BAD_REQUEST,
			                    "\"name\" has a control character");
	if (pt[3] == 0 && pt[4] == 0 && pt[5] == 0)
		return cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		                    "\"point\": the normal (elements 4..6) is "
		                    "zero");
	int slot = -1;
	int rc = cmd_mb_sensor_add(r->d, j, name, pt, &slot);
	if (rc == -2)
		return cmd_req_fail(r, RP_ERR_STATE,
		                    "job %llu already has a sensor '%s'",
		                    (unsigned long long)j->id, name);
	if (rc != 0)
		return cmd_req_fail(r, RP_ERR_NOMEM, "out of memory");
	json_t *reply = rp_reply_ok(r->id);
	json_object_set_new(reply, "job", json_integer((json_int_t)j->id));
	json_object_set_new(reply, "name", json_string(name));
	json_object_set_new(reply, "slot",
	                    slot >= 0 ? json_integer(slot) : json_null());
	return record_sensor(r, j->id, name, pt, reply);
}

cmd_result cmd_sensor_list(cmd_req *r)
{
	int failed;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return CMD_ERROR;
	size_t n;
	const cmd_sensor *x = cmd_mb_sensors(r->d, j, &n);
	json_t *arr = json_array();
	for (size_t i = 0; i < n; i++)
		json_array_append_new(arr, sensor_json(r->d, j->id, &x[i]));
	json_object_set_new(r->res, "job", json_integer((json_int_t)j->id));
	json_object_set_new(r->res, "sensors", arr);
	return CMD_REPLY;
}
