/*
 * options.c -- the engine's options as data: the rows of RAD_OPTIONS
 * (rad.h), their defaults and checks, and the accuracy knob.
 *
 * Everything that reads or writes an option by name (luxrad-solve's
 * command line, the daemon's job.create, the client, the docs test) goes
 * through rad_option_defs, so a range, a default or a choice is written
 * once, in rad.h.  rad_solver_new checks a whole rad_options against the
 * same rows (rad_options_check), so a value no front end would accept is
 * refused by the engine as well, with the same message.
 *
 * This file and error.c are their own small library (luxrad_options),
 * which the engine links and so does the thin client: it checks and
 * documents the options without the engine's Embree or threads.
 */
#include "rad.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#define RAD_OPT_CHOICES_(field, key, cli, type, def, lo, hi, range, choices,   \
                         ...)                                                  \
	static const char *const choices_##field[] = {choices, NULL};
RAD_OPTIONS(RAD_OPT_CHOICES_)
#undef RAD_OPT_CHOICES_

const rad_option_def rad_option_defs[RAD_NOPTIONS] = {
#define RAD_OPT_ROW_(field, key, cli, type, def, lo, hi, range, choices,       \
                     metavar, unit, help)                                      \
	{key,                                                                  \
	 cli,                                                                  \
	 RAD_OPT_##type,                                                       \
	 offsetof(rad_options, field),                                         \
	 def,                                                                  \
	 lo,                                                                   \
	 hi,                                                                   \
	 range,                                                                \
	 RAD_OPT_##type == RAD_OPT_ENUM ? choices_##field : NULL,              \
	 metavar,                                                              \
	 unit,                                                                 \
	 help},
        RAD_OPTIONS(RAD_OPT_ROW_)
#undef RAD_OPT_ROW_
};

const rad_option_def *rad_option_find(const char *key)
{
	for (int i = 0; i < RAD_NOPTIONS; i++)
		if (strcmp(rad_option_defs[i].key, key) == 0)
			return &rad_option_defs[i];
	return NULL;
}

const rad_option_def *rad_option_find_cli(const char *cli, size_t len)
{
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const char *c = rad_option_defs[i].cli;
		if (strlen(c) == len && strncmp(c, cli, len) == 0)
			return &rad_option_defs[i];
	}
	return NULL;
}

double rad_option_get(const rad_options *o, const rad_option_def *d)
{
	const char *p = (const char *)o + d->offset;
	if (d->type == RAD_OPT_DOUBLE)
		return *(const double *)p;
	return *(const int *)p;
}

static int in_range(const rad_option_def *d, double v)
{
	if (!isfinite(v))
		return 0;
	if ((d->range & RAD_RANGE_LO_OPEN) ? v <= d->lo : v < d->lo)
		return 0;
	return (d->range & RAD_RANGE_HI_OPEN) ? v < d->hi : v <= d->hi;
}

void rad_option_range_text(const rad_option_def *d, char *buf, size_t len)
{
	if (d->type == RAD_OPT_BOOL)
		snprintf(buf, len, "true or false");
	else if (d->type == RAD_OPT_ENUM) {
		size_t n = 0;
		buf[0] = '\0';
		for (int i = 0; d->choices[i] && n < len; i++)
			n += (size_t)snprintf(buf + n, len - n, "%s%s",
			                      i ? ", " : "one of ",
			                      d->choices[i]);
	} else if (d->hi == HUGE_VAL)
		snprintf(buf, len, "%s %g",
		         (d->range & RAD_RANGE_LO_OPEN) ? ">" : ">=", d->lo);
	else
		snprintf(buf, len, "in %c%g, %g%c",
		         (d->range & RAD_RANGE_LO_OPEN) ? '(' : '[', d->lo,
		         d->hi, (d->range & RAD_RANGE_HI_OPEN) ? ')' : ']');
}

void rad_option_default_text(const rad_option_def *d, char *buf, size_t len)
{
	int k = (int)d->def;
	if (d->type == RAD_OPT_BOOL)
		snprintf(buf, len, "%s", k ? "true" : "false");
	else if (d->type == RAD_OPT_ENUM)
		snprintf(buf, len, "%s", d->choices[k]);
	else
		snprintf(buf, len, "%g", d->def);
}

int rad_option_choice(const rad_option_def *d, const char *name)
{
	for (int i = 0; d->choices && d->choices[i]; i++)
		if (strcmp(d->choices[i], name) == 0)
			return i;
	return -1;
}

/* Whether v is a value d accepts, with the message when it is not. */
static rad_status check_value(const rad_option_def *d, double v, rad_error *err)
{
	char rng[128];
	if (in_range(d, v) && (d->type == RAD_OPT_DOUBLE || v == floor(v)))
		return RAD_OK;
	rad_option_range_text(d, rng, sizeof(rng));
	if (d->type == RAD_OPT_INT)
		return rad_fail(err, RAD_ERR_INVALID,
		                "option \"%s\" must be an integer %s (got %g)",
		                d->key, rng, v);
	return rad_fail(err, RAD_ERR_INVALID,
	                "option \"%s\" must be %s (got %g)", d->key, rng, v);
}

rad_status rad_option_set(rad_options *o, const rad_option_def *d, double v,
                          rad_error *err)
{
	rad_status st = check_value(d, v, err);
	if (st != RAD_OK)
		return st;
	if (d == &rad_option_defs[RAD_OPT_accuracy])
		return rad_options_accuracy(o, v, err);
	char *p = (char *)o + d->offset;
	if (d->type == RAD_OPT_DOUBLE)
		*(double *)p = v;
	else
		*(int *)p = (int)v;
	return RAD_OK;
}

rad_status rad_options_check(const rad_options *o, rad_error *err)
{
	if ((unsigned)o->solver >= RAD_SOLVER_NKINDS)
		return rad_fail(err, RAD_ERR_INVALID, "unknown solver %d",
		                (int)o->solver);
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		rad_status st = check_value(d, rad_option_get(o, d), err);
		if (st != RAD_OK)
			return st;
	}
	return RAD_OK;
}

/*
 * The table's defaults, then the accuracy knob at its default over them:
 * the options it sets get its arithmetic (0.02 / 20, not the literal
 * 1e-3), so that results stay the same to the bit whichever way a front
 * end arrives at the default.
 */
void rad_options_default(rad_options *o)
{
	memset(o, 0, sizeof(*o));
	o->solver = RAD_SOLVER_HR;
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		char *p = (char *)o + d->offset;
		if (d->type == RAD_OPT_DOUBLE)
			*(double *)p = d->def;
		else
			*(int *)p = (int)d->def;
	}
	rad_options_accuracy(o, RAD_ACCURACY_DEFAULT, NULL);
}

/*
 * What one accuracy R asks of each knob.  The query's gather gets half of
 * the budget; the solution the rest: the convergence tolerance a
 * twentieth (the iteration error is cheap to remove), the link threshold
 * eps (a flux fraction: a link's error is second order in its size) and,
 * for looser R only, the receiver variation in proportion.  At the
 * default R = 0.02 these are the defaults of rad.h's table (eps 1e-4,
 * variation 0.5, convergence 1e-3, query tolerance 1e-2; test_options
 * checks that they agree).  A variation finer than 0.5 makes points a few
 * centimetres from a corner (floor and two walls) brighter, not closer
 * (the office's floor corners: +3.4 % at 0.5, +12.7 % at 0.25, against
 * luxrad-reference; README, Limitations), and bought little elsewhere in
 * the validation study (Cornell box, obstructed source, bright hall,
 * closed boxes and room: within 0.4 % at --accuracy 0.01), so a tighter R
 * leaves it at 0.5 until leaves near corners are right.
 */
rad_status rad_options_accuracy(rad_options *o, double accuracy, rad_error *err)
{
	rad_status st =
	        check_value(&rad_option_defs[RAD_OPT_accuracy], accuracy, err);
	if (st != RAD_OK)
		return st;
	double r = accuracy / RAD_ACCURACY_DEFAULT;
	o->accuracy = accuracy;
	o->query_tol = accuracy / 2;
	o->converge_tol = accuracy / 20;
	o->eps = 1e-4 * r * r;
	o->variation = 0.5 * fmax(r, 1.0);
	return RAD_OK;
}
