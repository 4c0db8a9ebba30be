/*
 * report_html.c -- the HTML of luxrad report: escaping, numbers, images
 * embedded as data: URIs, the page frame with its inline CSS, and the
 * summary tables (scene, job, luminaires, accuracy, cost) read from the
 * daemon's job.info and scene.info replies.
 *
 * The page is one file with nothing to fetch: no scripts, no fonts, no
 * external style sheets or images, so it opens the same offline, in a
 * mail attachment or an archive.  Every string that came from the scene
 * file or the daemon (names above all) goes through lx_html_text.
 */
#include <stdio.h>
#include <string.h>

#include "client.h"

void lx_html_text(FILE *f, const char *s)
{
	for (; s && *s; s++) {
		switch (*s) {
		case '&':
			fputs("&amp;", f);
			break;
		case '<':
			fputs("&lt;", f);
			break;
		case '>':
			fputs("&gt;", f);
			break;
		case '"':
			fputs("&quot;", f);
			break;
		case '\'':
			fputs("&#39;", f);
			break;
		default:
			fputc(*s, f);
		}
	}
}

void lx_html_num(FILE *f, const json_t *o, const char *k, const char *fmt)
{
	json_t *v = json_object_get(o, k);
	if (json_is_number(v))
		fprintf(f, fmt, json_number_value(v));
	else
		fputs("&ndash;", f);
}

void lx_html_png(FILE *f, const unsigned char *png, size_t len, const char *alt)
{
	static const char b64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnop"
	                          "qrstuvwxyz0123456789+/";
	fputs("<img alt=\"", f);
	lx_html_text(f, alt);
	fputs("\" src=\"data:image/png;base64,", f);
	for (size_t i = 0; i < len; i += 3) {
		unsigned v = (unsigned)png[i] << 16;
		if (i + 1 < len)
			v |= (unsigned)png[i + 1] << 8;
		if (i + 2 < len)
			v |= png[i + 2];
		fputc(b64[(v >> 18) & 63], f);
		fputc(b64[(v >> 12) & 63], f);
		fputc(i + 1 < len ? b64[(v >> 6) & 63] : '=', f);
		fputc(i + 2 < len ? b64[v & 63] : '=', f);
	}
	fputs("\">", f);
}

void lx_html_head(FILE *f, const char *title)
{
	fputs("<!DOCTYPE html>\n<html lang=\"en\"><head><meta "
	      "charset=\"utf-8\">\n<title>",
	      f);
	lx_html_text(f, title);
	fputs("</title>\n<style>\n"
	      "body{font:14px/1.4 system-ui,sans-serif;margin:2em auto;"
	      "max-width:1100px;color:#222;padding:0 1em}\n"
	      "h1{font-size:1.6em;margin-bottom:0}h2{margin-top:1.6em;"
	      "border-bottom:1px solid #ccc}\n"
	      "table{border-collapse:collapse;margin:.5em 0}\n"
	      "th,td{border:1px solid #ccc;padding:3px 8px;text-align:left}\n"
	      "td.n{text-align:right;font-variant-numeric:tabular-nums}\n"
	      "th{background:#f0f0f0}\n"
	      "figure{display:inline-block;margin:.5em 1em .5em 0;"
	      "vertical-align:top}\n"
	      "figcaption{font-size:.9em;color:#555;max-width:560px}\n"
	      ".note{color:#555;font-size:.9em}\n"
	      "</style></head><body>\n<h1>",
	      f);
	lx_html_text(f, title);
	fputs("</h1>\n", f);
}

void lx_html_foot(FILE *f)
{
	fputs("<p class=\"note\">Written by luxrad " LX_VERSION
	      " (protocol 1). Illuminance in lux, lengths in metres; "
	      "U<sub>0</sub> = E<sub>min</sub>/E<sub>m</sub>, "
	      "U<sub>d</sub> = E<sub>min</sub>/E<sub>max</sub>; grid "
	      "spacing after EN 12464-1, p = 0.2&middot;5<sup>log<sub>10"
	      "</sub>d</sup>.</p>\n</body></html>\n",
	      f);
}

/* A table row: header cell, then a value cell from o[k]. */
static void row_num(FILE *f, const char *th, const json_t *o, const char *k,
                    const char *fmt)
{
	fprintf(f, "<tr><th>%s</th><td class=\"n\">", th);
	lx_html_num(f, o, k, fmt);
	fputs("</td></tr>\n", f);
}

static void row_text(FILE *f, const char *th, const char *text)
{
	fprintf(f, "<tr><th>%s</th><td>", th);
	lx_html_text(f, text);
	fputs("</td></tr>\n", f);
}

static void scene_table(FILE *f, const json_t *scene)
{
	const json_t *c = json_object_get(scene, "counts");
	const json_t *b = json_object_get(scene, "bounds");
	const json_t *lo = json_object_get(b, "min"),
	             *hi = json_object_get(b, "max");
	fputs("<h2>Scene</h2>\n<table>\n", f);
	row_text(f, "Name", lx_jstr(scene, "name"));
	row_num(f, "Scene id", scene, "scene", "%.0f");
	row_num(f, "Polygons", c, "polygons", "%.0f");
	row_num(f, "Nodes", c, "nodes", "%.0f");
	row_num(f, "Materials", c, "materials", "%.0f");
	row_num(f, "Back faces (two-sided)", c, "back_faces", "%.0f");
	const json_t *tex = json_object_get(scene, "textures");
	row_num(f, "Textured materials", tex, "read", "%.0f");
	row_num(f, "Textured triangles", tex, "textured_triangles", "%.0f");
	const char *warn = lx_jstr(scene, "warnings");
	if (warn && *warn)
		row_text(f, "Importer notes", warn);
	fputs("<tr><th>Extent (m)</th><td class=\"n\">", f);
	for (int k = 0; k < 3; k++)
		fprintf(f, "%s%.3f", k ? " &times; " : "",
		        json_number_value(json_array_get(hi, (size_t)k)) -
		                json_number_value(
		                        json_array_get(lo, (size_t)k)));
	fputs("</td></tr>\n</table>\n", f);
}

static void luminaires(FILE *f, const json_t *scene)
{
	const json_t *lum = json_object_get(scene, "luminaires"), *x;
	const json_t *lights = json_object_get(lum, "lights");
	const json_t *em = json_object_get(lum, "emitters");
	size_t i;
	fputs("<h2>Luminaires</h2>\n", f);
	if (json_array_size(em) > 0) {
		fputs("<table><tr><th>Emitting surface</th><th>Polygons</th>"
		      "<th>Area (m&sup2;)</th><th>Exitance (lux)</th>"
		      "<th>Flux (lm)</th></tr>\n",
		      f);
		json_array_foreach(em, i, x)
		{
			fputs("<tr><td>", f);
			lx_html_text(f, lx_jstr(x, "name"));
			fputs("</td><td class=\"n\">", f);
			lx_html_num(f, x, "polygons", "%.0f");
			fputs("</td><td class=\"n\">", f);
			lx_html_num(f, x, "area", "%.4g");
			fputs("</td><td class=\"n\">", f);
			lx_html_num(f, x, "exitance_lux", "%.4g");
			fputs("</td><td class=\"n\">", f);
			lx_html_num(f, x, "flux_lm", "%.4g");
			fputs("</td></tr>\n", f);
		}
		fputs("</table>\n", f);
	}
	if (json_array_size(lights) > 0) {
		fputs("<table><tr><th>Light</th><th>Kind</th><th>Intensity"
		      "</th><th>Flux (lm)</th><th>Opening (m)</th>"
		      "<th>Position (m)</th></tr>\n",
		      f);
		json_array_foreach(lights, i, x)
		{
			const json_t *p = json_object_get(x, "position");
			fputs("<tr><td>", f);
			lx_html_text(f, lx_jstr(x, "name"));
			fputs("</td><td>", f);
			lx_html_text(f, lx_jstr(x, "kind"));
			fputs("</td><td class=\"n\">", f);
			if (json_object_get(x, "lux"))
				lx_html_num(f, x, "lux", "%.4g lux");
			else
				lx_html_num(f, x, "candela", "%.4g cd");
			fputs("</td><td class=\"n\">", f);
			if (json_object_get(x, "lumens"))
				lx_html_num(f, x, "lumens", "%.4g");
			fputs("</td><td class=\"n\">", f);
			const json_t *op = json_object_get(x, "opening_m");
			double o0 = json_number_value(json_array_get(op, 0));
			double o1 = json_number_value(json_array_get(op, 1));
			if (json_is_true(json_object_get(x, "opening_round")))
				fprintf(f, "&#8960; %.3g", o0);
			else if (o0 > 0 || o1 > 0)
				fprintf(f, "%.3g &times; %.3g", o0, o1);
			fputs("</td><td class=\"n\">", f);
			for (size_t k = 0; k < json_array_size(p); k++)
				fprintf(f, "%s%.3f", k ? ", " : "",
				        json_number_value(
				                json_array_get(p, k)));
			fputs("</td></tr>\n", f);
		}
		fputs("</table>\n", f);
	}
	if (!json_array_size(em) && !json_array_size(lights))
		fputs("<p>The scene reports no luminaires.</p>\n", f);
	if (json_is_true(json_object_get(lum, "more")))
		fputs("<p class=\"note\">More luminaires than listed.</p>\n",
		      f);
}

static void job_tables(FILE *f, const json_t *job)
{
	const json_t *opt = json_object_get(job, "options");
	const json_t *st = json_object_get(job, "stats");
	const json_t *mem = json_object_get(st, "memory");
	char buf[64];
	fputs("<h2>Solve: accuracy and cost</h2>\n<table>\n", f);
	row_text(f, "Job", lx_jstr(job, "name"));
	row_text(f, "Solver", lx_jstr(job, "solver"));
	row_text(f, "State", lx_jstr(job, "state"));
	row_num(f, "Accuracy asked (relative)", opt, "accuracy", "%.3g");
	row_num(f, "Convergence tolerance", opt, "tol", "%.3g");
	row_num(f, "Query tolerance", opt, "query_tol", "%.3g");
	row_num(f, "Estimated remaining error (relative)", st, "error_estimate",
	        "%.3g");
	row_text(f, "Converged",
	         json_is_true(json_object_get(st, "converged")) ? "yes" : "no");
	row_num(f, "Iterations", st, "iteration", "%.0f");
	row_num(f, "Solve time (s)", st, "seconds_total", "%.3f");
	row_text(f, "Memory, peak",
	         lx_jbytes(mem, "peak_bytes", buf, sizeof buf));
	row_text(f, "Memory, now",
	         lx_jbytes(mem, "total_bytes", buf, sizeof buf));
	row_num(f, "Links stored", json_object_get(st, "links"), "stored",
	        "%.0f");
	row_num(f, "Mesh elements (leaves)", st, "leaves", "%.0f");
	fputs("</table>\n", f);
}

void lx_html_summary(FILE *f, const json_t *job, const json_t *scene)
{
	scene_table(f, scene);
	luminaires(f, scene);
	job_tables(f, job);
}
