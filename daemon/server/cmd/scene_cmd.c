/*
 * scene_cmd.c -- the scene.* commands: upload, list, info, delete.
 *
 * Uploads and deletions run on the store thread (a large upload parses
 * for seconds); the upload task takes the connection's input buffer with
 * the payload in it instead of copying it.  scene.delete refuses while a
 * job uses the scene (njobs counts jobs being created too) and removes it
 * from the registry at once (status stops counting it); the engine scene
 * is freed when the last reference goes (core/scenes.c).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "log.h"

/* ----------------------------------------------------------------- upload */

typedef struct upload_task {
	srv_task t;
	unsigned char *buf;           /* the connection's input buffer */
	const unsigned char *payload; /* inside buf */
	size_t len;
	char name[256];
	char owner[64];
	srv_scene *sc; /* result */
	rp_err code;   /* error */
	char msg[600];
} upload_task;

static void upload_run(srv *s, srv_task *t)
{
	upload_task *u = (upload_task *)t;
	rad_error err = {0};
	uint64_t refusals = rad_mem_limit_refusals();

	int rc = srv_scene_create(s, u->name, u->owner, u->payload, u->len,
	                          &u->sc, &err);
	if (rc == -1) {
		u->code = cmd_err_from_rad(err.code);
		snprintf(u->msg, sizeof(u->msg), "scene refused: %s", err.msg);
		if (err.code == RAD_ERR_NOMEM)
			srv_memory_note(s, refusals, u->msg, sizeof(u->msg));
	} else if (rc != 0) {
		u->code = RP_ERR_IO;
		snprintf(u->msg, sizeof(u->msg), "cannot store the scene: %s",
		         err.msg);
	}
	free(u->buf);
	u->buf = NULL;
}

static void upload_done(srv *s, srv_task *t)
{
	upload_task *u = (upload_task *)t;
	json_t *reply;

	s->scenes_pending--;
	if (u->sc) {
		srv_scene_register(s, u->sc);
		reply = rp_reply_ok(t->id);
		json_t *body = srv_scene_json(u->sc);
		json_object_update(reply, body);
		json_decref(body);
	} else {
		reply = rp_reply_error(t->id, u->code, "%s", u->msg);
	}
	cmd_task_reply(s, t, reply);
}

cmd_result cmd_scene_upload(cmd_req *r)
{
	srv *s = r->s;
	const char *name = NULL;

	if (rp_arg_string(r->hdr, "name", 0, &name, &r->err) < 0)
		return CMD_ERROR;
	if (name && strlen(name) > 255)
		return cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		                    "\"name\" is longer than 255 bytes");
	if (!r->payload)
		return cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		                    "scene.upload needs the scene as a payload "
		                    "(\"bytes\": N, then N bytes)");
	if (s->nscenes + s->scenes_pending >= s->cfg.max_scenes)
		return cmd_req_fail(r, RP_ERR_LIMIT,
		                    "max_scenes (%d) scenes exist: delete one "
		                    "first",
		                    s->cfg.max_scenes);
	if (cmd_req_memory_full(r))
		return CMD_ERROR;
	upload_task *u = calloc(1, sizeof(*u));
	if (!u)
		return cmd_req_fail(r, RP_ERR_NOMEM, "out of memory");
	size_t off = (size_t)(r->payload - (r->c->in + r->c->in_off));
	size_t in_off = r->c->in_off;
	u->buf = cmd_conn_steal_input(r->c, r->frame_used);
	if (!u->buf) {
		free(u);
		return cmd_req_fail(r, RP_ERR_NOMEM, "out of memory");
	}
	u->payload = u->buf + in_off + off;
	u->len = r->payload_len;
	snprintf(u->name, sizeof(u->name), "%s", name ? name : "");
	snprintf(u->owner, sizeof(u->owner), "%s", r->c->user);
	s->scenes_pending++;
	return cmd_req_defer(r, &s->store_pool, &u->t, upload_run, upload_done);
}

/* ------------------------------------------------------------ list / info */

cmd_result cmd_scene_list(cmd_req *r)
{
	json_t *arr = json_array();
	for (srv_scene *sc = r->s->scenes; sc; sc = sc->next) {
		if (!cmd_visible(r->c, sc->owner))
			continue;
		json_t *o = json_object();
		json_object_set_new(o, "id", json_integer((json_int_t)sc->id));
		json_object_set_new(o, "name", json_string(sc->name));
		json_object_set_new(o, "owner", json_string(sc->owner));
		json_object_set_new(o, "bytes",
		                    json_integer((json_int_t)sc->bytes));
		json_object_set_new(o, "polygons",
		                    json_integer(sc->counts.polygons));
		json_object_set_new(o, "jobs", json_integer(sc->njobs));
		json_object_set_new(o, "memory_bytes",
		                    json_integer(sc->mem.total));
		json_object_set_new(o, "created", json_real(sc->created));
		json_array_append_new(arr, o);
	}
	json_object_set_new(r->res, "scenes", arr);
	return CMD_REPLY;
}

/*
 * scene.info's "luminaires": the scene's lights and its emitting surfaces
 * per node, LUMINAIRES_MAX of each at most ("more" says when there were
 * more), in the few numbers a report shows.
 */
#define LUMINAIRES_MAX 256

static json_t *lights_json(const rad_scene *sc, uint32_t n)
{
	static const char *const kinds[] = {"point", "spot", "directional"};
	json_t *arr = json_array();
	for (uint32_t i = 0; i < n && i < LUMINAIRES_MAX; i++) {
		rad_light_desc l;
		if (rad_scene_light_get(sc, i, &l, NULL) != RAD_OK)
			break;
		json_t *o = json_pack(
		        "{s:s, s:s, s:f}", "name", l.name ? l.name : "", "kind",
		        kinds[l.kind <= RAD_LIGHT_DIRECTIONAL ? l.kind : 0],
		        l.kind == RAD_LIGHT_DIRECTIONAL ? "lux" : "candela",
		        rad_luma3(l.intensity));
		if (l.kind != RAD_LIGHT_DIRECTIONAL)
			json_object_set_new(o, "position",
			                    json_pack("[fff]", l.position[0],
			                              l.position[1],
			                              l.position[2]));
		if (l.kind != RAD_LIGHT_POINT)
			json_object_set_new(o, "direction",
			                    json_pack("[fff]", l.direction[0],
			                              l.direction[1],
			                              l.direction[2]));
		if (l.kind == RAD_LIGHT_SPOT)
			json_object_set_new(
			        o, "outer_cone_deg",
			        json_real(l.outer_cone * 180 / M_PI));
		if (l.candela) { /* a photometric file's table */
			double k = rad_luma3(l.intensity);
			json_object_set_new(o, "kind",
			                    json_string("photometric"));
			json_object_set_new(
			        o, "candela",
			        json_real(k * rad_candela_peak(l.candela)));
			json_object_set_new(
			        o, "lumens",
			        json_real(k * rad_candela_flux(l.candela)));
			json_object_set_new(
			        o, "opening_m",
			        json_pack("[ff]", l.opening[0], l.opening[1]));
			json_object_set_new(o, "opening_round",
			                    json_boolean(l.opening_round));
		}
		json_array_append_new(arr, o);
	}
	return arr;
}

static json_t *luminaires_json(const srv_scene *s)
{
	static rad_emitter em[LUMINAIRES_MAX]; /* I/O thread only */
	int more;
	uint32_t n = rad_scene_emitters(s->scene, em, LUMINAIRES_MAX, &more);
	json_t *arr = json_array();
	for (uint32_t i = 0; i < n; i++)
		json_array_append_new(
		        arr,
		        json_pack("{s:i, s:s, s:i, s:f, s:f, s:f}", "node",
		                  (int)em[i].node, "name",
		                  rad_scene_node_name(s->scene, em[i].node),
		                  "polygons", (int)em[i].polygons, "area",
		                  em[i].area_m2, "exitance_lux",
		                  rad_luma3(em[i].exitance), "flux_lm",
		                  em[i].flux_lm));
	return json_pack("{s:o, s:o, s:b}", "lights",
	                 lights_json(s->scene, s->counts.lights), "emitters",
	                 arr, "more",
	                 more || s->counts.lights > LUMINAIRES_MAX);
}

cmd_result cmd_scene_info(cmd_req *r)
{
	srv_scene *sc = cmd_req_scene(r);
	if (!sc)
		return CMD_ERROR;
	json_t *body = srv_scene_json(sc), *jobs = json_array();
	for (srv_job *j = r->s->jobs; j; j = j->next)
		if (j->scene == sc && cmd_visible(r->c, j->owner))
			json_array_append_new(jobs,
			                      json_integer((json_int_t)j->id));
	json_object_update(r->res, body);
	json_decref(body);
	json_object_set_new(r->res, "jobs", jobs);
	json_object_set_new(r->res, "luminaires", luminaires_json(sc));
	return CMD_REPLY;
}

/* ----------------------------------------------------------------- delete */

typedef struct scene_del_task {
	srv_task t;
	uint64_t scene;
	int failed;
	char msg[512];
} scene_del_task;

static void scene_del_run(srv *s, srv_task *t)
{
	scene_del_task *dt = (scene_del_task *)t;
	dt->failed =
	        srv_scene_forget(s, dt->scene, dt->msg, sizeof(dt->msg)) != 0;
}

static void scene_del_done(srv *s, srv_task *t)
{
	scene_del_task *dt = (scene_del_task *)t;
	json_t *reply;
	if (dt->failed)
		reply = rp_reply_error(
		        t->id, RP_ERR_IO,
		        "scene %llu was freed but its file could "
		        "not be removed: %s",
		        (unsigned long long)dt->scene, dt->msg);
	else
		reply = rp_reply_ok(t->id);
	cmd_task_reply(s, t, reply);
}

cmd_result cmd_scene_delete(cmd_req *r)
{
	srv *s = r->s;
	srv_scene *sc = cmd_req_scene(r);
	if (!sc)
		return CMD_ERROR;
	if (sc->njobs > 0)
		return cmd_req_fail(r, RP_ERR_BUSY,
		                    "scene %llu is used by %d job%s: delete "
		                    "them first",
		                    (unsigned long long)sc->id, sc->njobs,
		                    sc->njobs == 1 ? "" : "s");
	scene_del_task *dt = calloc(1, sizeof(*dt));
	if (!dt)
		return cmd_req_fail(r, RP_ERR_NOMEM, "out of memory");
	srv_scene_unregister(s, sc);
	dt->scene = sc->id;
	srv_scene_unref(sc);
	return cmd_req_defer(r, &s->store_pool, &dt->t, scene_del_run,
	                     scene_del_done);
}
