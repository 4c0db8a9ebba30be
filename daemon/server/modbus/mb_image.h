/*
 * mb_image.h -- the Modbus register image and its slot tables (private to
 * the Modbus module: the daemon uses modbus.h).
 *
 * An mb_image holds every register of the map (regmap.h) as a client
 * reads it, plus the jobs and sensors it knows with their slots and last
 * values.  Every call takes the image's mutex (a leaf lock) for its whole
 * duration and nothing else, so any thread may publish while the Modbus
 * thread reads.  The publication calls are those of modbus.h, minus the
 * server: see there for the slot rules and return values.
 */
#ifndef LUXRAD_SRV_MB_IMAGE_H
#define LUXRAD_SRV_MB_IMAGE_H

#include <stdint.h>

#include "modbus.h"

typedef struct mb_image mb_image;

/* An image with every slot empty; NULL when out of memory. */
mb_image *mb_image_new(const mb_config *c);
void mb_image_free(mb_image *im);

/* Copy [addr, addr + n) in one lock hold: 0, or exception code 2 / 3. */
int mb_image_read(mb_image *im, unsigned addr, unsigned n, uint16_t *out);

void mb_image_set_clients(mb_image *im, unsigned clients);
void mb_image_daemon(mb_image *im, const mb_daemon_vals *v);
int mb_image_job(mb_image *im, const mb_job_vals *v);
void mb_image_job_remove(mb_image *im, uint64_t job_id);
int mb_image_sensor(mb_image *im, uint64_t job_id, const char *name, double lux,
                    uint32_t iteration);
void mb_image_sensor_remove(mb_image *im, uint64_t job_id, const char *name);
int mb_image_job_slot(mb_image *im, uint64_t job_id);
int mb_image_sensor_slot(mb_image *im, uint64_t job_id, const char *name);

#endif
