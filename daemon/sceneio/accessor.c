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
	const sio_doc_view *bv = &d->views[a->buffer_view];
	if (bv->buffer < 0 || (size_t)bv->buffer >= d->nbuffers)
		return rad_fail(
		        err, RAD_ERR_INVALID,
		        "%s: bufferView %d: buffer %d out of range (%zu "
		        "buffers)",
		        where, a->buffer_view, bv->buffer, d->nbuffers);
	const sio_doc_buffer *b = &d->buffers[bv->buffer];
	if (bv->byte_offset > b->size ||
	    bv->byte_length > b->size - bv->byte_offset)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: bufferView %d (offset %zu, length %zu) "
		                "runs past the end of buffer %d (%zu bytes)",
		                where, a->buffer_view, bv->byte_offset,
		                bv->byte_length, bv->buffer, b->size);
	*out = bv;
	*buf = b;
	return RAD_OK;
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

rad_status sio_position_view(const sio_doc *d, const char *where, int ai,
                             sio_view *v, rad_error *err)
{
	const char *role = "POSITION accessor";
	const sio_doc_accessor *a = NULL;
	rad_status st = accessor_at(d, where, role, ai, &a, err);
	if (st != RAD_OK)
		return st;
	if (a->type != SIO_GL_VEC3 || a->component_type != SIO_GL_FLOAT)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: POSITION accessor %d must be VEC3 of "
		                "FLOAT (componentType 5126), not %s of "
		                "componentType %d",
		                where, ai, type_name(a->type),
		                a->component_type);
	return accessor_view(d, where, role, ai, 12, v, err);
}

rad_status sio_index_view(const sio_doc *d, const char *where, int ai,
                          sio_view *v, rad_error *err)
{
	const char *role = "index accessor";
	const sio_doc_accessor *a = NULL;
	rad_status st = accessor_at(d, where, role, ai, &a, err);
	if (st != RAD_OK)
		return st;
	size_t size = 0;
	switch (a->component_type) {
	case SIO_GL_UNSIGNED_BYTE:
		size = 1;
		break;
	case SIO_GL_UNSIGNED_SHORT:
		size = 2;
		break;
	case SIO_GL_UNSIGNED_INT:
		size = 4;
		break;
	}
	if (a->type != SIO_GL_SCALAR || size == 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "%s: index accessor %d must be SCALAR of "
		                "unsigned byte, short or int, not %s of "
		                "componentType %d",
		                where, ai, type_name(a->type),
		                a->component_type);
	return accessor_view(d, where, role, ai, size, v, err);
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
