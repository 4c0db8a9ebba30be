/*
 * accessor.c -- glTF accessors resolved to bytes: which buffer bytes an
 * accessor's elements occupy, checked before a byte is read.
 *
 * Every index (accessor, bufferView, buffer) is range-checked and every
 * element must lie inside its bufferView, and the bufferView inside its
 * buffer, with overflow-safe arithmetic: the document is hostile.  Each
 * failure names the primitive (where), the accessor's role and the view.
 * Alignment is not enforced: elements are read with memcpy.  Sparse
 * accessors and accessors without a bufferView (zero-filled) are not
 * supported.
 */
#include <string.h>

#include "internal.h"

static const char *type_name(int type)
{
	switch (type) {
	case SIO_GL_SCALAR:
		return "SCALAR";
	case SIO_GL_VEC2:
		return "VEC2";
	case SIO_GL_VEC3:
		return "VEC3";
	case SIO_GL_VEC4:
		return "VEC4";
	default:
		return "a matrix type";
	}
}

/* bufferView vi (range-checked) and its buffer, which must hold it. */
static rad_status view_in_buffer(const sio_doc *d, const char *where, int vi,
                                 const sio_doc_view **out,
                                 const sio_doc_buffer **buf, rad_error *err)
{
	const sio_doc_view *bv = &d->views[vi];
	if (bv->buffer < 0 || (size_t)bv->buffer >= d->nbuffers)
		return rad_fail(
		        err, RAD_ERR_INVALID,
		        "%s: bufferView %d: buffer %d out of range (%zu "
		        "buffers)",
		        where, vi, bv->buffer, d->nbuffers);
	const sio_doc_buffer *b = &d->buffers[bv->buffer];
	if (bv->byte_offset > b->size ||
	    bv->byte_length > b->size - bv->byte_offset)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: bufferView %d (offset %zu, length %zu) "
		                "runs past the end of buffer %d (%zu bytes)",
		                where, vi, bv->byte_offset, bv->byte_length,
		                bv->buffer, b->size);
	*out = bv;
	*buf = b;
	return RAD_OK;
}

/* The bufferView of accessor ai (already range-checked) and its bytes. */
static rad_status view_bytes(const sio_doc *d, const char *where,
                             const char *role, int ai, const sio_doc_view **out,
                             const sio_doc_buffer **buf, rad_error *err)
{
	const sio_doc_accessor *a = &d->accessors[ai];
	if (a->sparse)
		return rad_fail(err, RAD_ERR_UNSUPPORTED,
		                "%s: %s %d is sparse (not supported)", where,
		                role, ai);
	if (a->buffer_view < 0)
		return rad_fail(err, RAD_ERR_UNSUPPORTED,
		                "%s: %s %d has no bufferView (zero-filled "
		                "accessors are not supported)",
		                where, role, ai);
	if ((size_t)a->buffer_view >= d->nviews)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: %s %d: bufferView %d out of range (%zu "
		                "bufferViews)",
		                where, role, ai, a->buffer_view, d->nviews);
	return view_in_buffer(d, where, a->buffer_view, out, buf, err);
}

/*
 * Resolve accessor ai (already range-checked) whose elements are elem
 * bytes.  where/role name it in messages ("mesh 2 'Chair' primitive 0",
 * "index accessor").
 */
static rad_status accessor_view(const sio_doc *d, const char *where,
                                const char *role, int ai, size_t elem,
                                sio_view *v, rad_error *err)
{
	const sio_doc_accessor *a = &d->accessors[ai];
	const sio_doc_view *bv = NULL;
	const sio_doc_buffer *b = NULL;
	rad_status st = view_bytes(d, where, role, ai, &bv, &b, err);
	if (st != RAD_OK)
		return st;
	size_t stride = bv->byte_stride ? bv->byte_stride : elem;
	if (stride < elem)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: bufferView %d: byteStride %zu is smaller "
		                "than one element of %s %d (%zu bytes)",
		                where, a->buffer_view, stride, role, ai, elem);
	if (a->count == 0)
		return rad_fail(err, RAD_ERR_INVALID, "%s: %s %d is empty",
		                where, role, ai);
	/* Overflow-safe form of offset + (count - 1) * stride + elem <= len */
	size_t avail = bv->byte_length;
	if (a->byte_offset > avail || elem > avail - a->byte_offset ||
	    a->count - 1 > (avail - a->byte_offset - elem) / stride)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: %s %d (offset %zu, count %zu, stride %zu) "
		                "reads past the end of bufferView %d (%zu "
		                "bytes)",
		                where, role, ai, a->byte_offset, a->count,
		                stride, a->buffer_view, avail);
	v->p = b->data + bv->byte_offset + a->byte_offset;
	v->stride = stride;
	v->count = a->count;
	v->size = elem;
	return RAD_OK;
}

/* Accessor ai of the primitive named where, range-checked. */
static rad_status accessor_at(const sio_doc *d, const char *where,
                              const char *role, int ai,
                              const sio_doc_accessor **a, rad_error *err)
{
	if (ai < 0 || (size_t)ai >= d->naccessors)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: %s %d out of range (%zu accessors)", where,
		                role, ai, d->naccessors);
	*a = &d->accessors[ai];
	return RAD_OK;
}

/* Bytes of a component of type ct, 0 for none we read. */
static size_t component_bytes(int ct)
{
	switch (ct) {
	case SIO_GL_UNSIGNED_BYTE:
		return 1;
	case SIO_GL_UNSIGNED_SHORT:
		return 2;
	case SIO_GL_UNSIGNED_INT:
	case SIO_GL_FLOAT:
		return 4;
	default:
		return 0;
	}
}

/*
 * Accessor ai as a view of elements of ncomp components of type `type`;
 * allowed lists the component types (0-terminated), integers only when
 * normalized if `norm`; must says all that in messages.
 */
static rad_status typed_view(const sio_doc *d, const char *where,
                             const char *role, int ai, int type, int ncomp,
                             const int *allowed, int norm, const char *must,
                             sio_view *v, rad_error *err)
{
	const sio_doc_accessor *a = NULL;
	rad_status st = accessor_at(d, where, role, ai, &a, err);
	if (st != RAD_OK)
		return st;
	int ok = 0;
	for (const int *ct = allowed; *ct; ct++)
		ok |= a->component_type == *ct &&
		      (!norm || *ct == SIO_GL_FLOAT || a->normalized);
	if (a->type != type || !ok)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: %s %d must be %s, not %s of componentType "
		                "%d",
		                where, role, ai, must, type_name(a->type),
		                a->component_type);
	return accessor_view(d, where, role, ai,
	                     ncomp * component_bytes(a->component_type), v,
	                     err);
}

rad_status sio_position_view(const sio_doc *d, const char *where, int ai,
                             sio_view *v, rad_error *err)
{
	static const int allowed[] = {SIO_GL_FLOAT, 0};
	return typed_view(d, where, "POSITION accessor", ai, SIO_GL_VEC3, 3,
	                  allowed, 0, "VEC3 of FLOAT (componentType 5126)", v,
	                  err);
}

rad_status sio_index_view(const sio_doc *d, const char *where, int ai,
                          sio_view *v, rad_error *err)
{
	static const int allowed[] = {SIO_GL_UNSIGNED_BYTE,
	                              SIO_GL_UNSIGNED_SHORT,
	                              SIO_GL_UNSIGNED_INT, 0};
	return typed_view(d, where, "index accessor", ai, SIO_GL_SCALAR, 1,
	                  allowed, 0, "SCALAR of unsigned byte, short or int",
	                  v, err);
}

/* glTF data is little-endian, as is x86. */
size_t sio_index_at(const sio_view *v, size_t k)
{
	const unsigned char *p = v->p + k * v->stride;
	if (v->size == 1)
		return p[0];
	if (v->size == 2) {
		uint16_t x;
		memcpy(&x, p, 2);
		return x;
	}
	uint32_t x;
	memcpy(&x, p, 4);
	return x;
}

rad_status sio_uv_view(const sio_doc *d, const char *where, int ai, sio_view *v,
                       rad_error *err)
{
	static const int allowed[] = {SIO_GL_FLOAT, SIO_GL_UNSIGNED_BYTE,
	                              SIO_GL_UNSIGNED_SHORT, 0};
	return typed_view(d, where, "TEXCOORD accessor", ai, SIO_GL_VEC2, 2,
	                  allowed, 1,
	                  "VEC2 of FLOAT or of normalized unsigned byte or "
	                  "short",
	                  v, err);
}

void sio_uv_at(const sio_view *v, size_t k, double uv[2])
{
	const unsigned char *p = v->p + k * v->stride;
	for (int i = 0; i < 2; i++) {
		if (v->size == 8) {
			float x;
			memcpy(&x, p + 4 * i, 4);
			uv[i] = x;
		} else if (v->size == 2) {
			uv[i] = p[i] / 255.0;
		} else {
			uint16_t x;
			memcpy(&x, p + 2 * i, 2);
			uv[i] = x / 65535.0;
		}
	}
}

rad_status sio_view_bytes(const sio_doc *d, const char *where, int vi,
                          const unsigned char **p, size_t *len, rad_error *err)
{
	if (vi < 0 || (size_t)vi >= d->nviews)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: bufferView %d out of range (%zu "
		                "bufferViews)",
		                where, vi, d->nviews);
	const sio_doc_view *bv = NULL;
	const sio_doc_buffer *b = NULL;
	rad_status st = view_in_buffer(d, where, vi, &bv, &b, err);
	if (st != RAD_OK)
		return st;
	*p = b->data + bv->byte_offset;
	*len = bv->byte_length;
	return RAD_OK;
}
