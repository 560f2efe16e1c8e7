/* Byte planes of integer and float columns: columns.write_packed and columns.float_deltas
 * in C (issue 14, thirteenth pass).
 *
 * Both are a few passes of integer arithmetic over a column of 200 values, which numpy
 * does in microseconds but in a dozen calls each, and its calls cost more than its work:
 * a window's packed stamps, its two packed int columns and its float deltas took 160 us of
 * the encoder's ~930 per 200 odometry messages, most of it call overhead. The Python
 * functions stay the reference; the two paths give the same bytes
 * (tests/codecs/test_planes_compiled.py). docs/CODEC_COLUMNAR.md specifies the layouts.
 *
 * pack_ints(words, offset) -> bytes: packed(n) of the i64 values (offset(n) if `offset`),
 *   header included. `words` is a C-contiguous buffer of n little-endian i64.
 * float_planes(bits, k, n) -> (orders, planes): for k rows of n f64 bits (a C-contiguous
 *   buffer of k * n little-endian i64), each row's delta order in 1..3 and one bytes of
 *   k * 8 * n: row j's 8 planes of n bytes at 8 * n * j.
 *
 * Values are read and written byte by byte in little-endian order, as the format is, so
 * the helper gives the same bytes on any host. Optional: cclogfs works without it.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

/* Orders of FLOAT_DELTA (columnar_format.FLOAT_ORDERS) and the sample that ranks them
 * (columns._ORDER_SAMPLES). */
#define TOP_ORDER 3
#define ORDER_SAMPLES 64

static uint64_t load_u64(const unsigned char *p)
{
    uint64_t v = 0;
    for (int b = 7; b >= 0; b--)
        v = (v << 8) | p[b];
    return v;
}

static unsigned char *store_u64(unsigned char *p, uint64_t v)
{
    for (int b = 0; b < 8; b++)
        p[b] = (unsigned char)(v >> (8 * b));
    return p + 8;
}

static uint64_t gcd_u64(uint64_t a, uint64_t b)
{
    while (b) {
        uint64_t t = a % b;
        a = b;
        b = t;
    }
    return a;
}

/* int64 arithmetic that wraps modulo 2^64, as numpy's does: done in uint64. */
static int64_t wrap_sub(int64_t a, int64_t b)
{
    return (int64_t)((uint64_t)a - (uint64_t)b);
}

static uint64_t zigzag(int64_t v)
{
    return ((uint64_t)v << 1) ^ (uint64_t)(v >> 63);
}

/* Byte b of every value, for b < width: the planes that follow a column's header. */
static void write_planes(unsigned char *out, const uint64_t *z, Py_ssize_t count, int width)
{
    for (int b = 0; b < width; b++)
        for (Py_ssize_t i = 0; i < count; i++)
            *out++ = (unsigned char)(z[i] >> (8 * b));
}

static int get_words(PyObject *obj, Py_buffer *view, Py_ssize_t *count)
{
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS) < 0)
        return -1;
    if (view->len % 8) {
        PyBuffer_Release(view);
        PyErr_SetString(PyExc_ValueError, "a buffer of i64 values must be a multiple of 8 bytes long");
        return -1;
    }
    *count = view->len / 8;
    return 0;
}

static PyObject *pack_ints(PyObject *self, PyObject *args)
{
    PyObject *obj;
    int offset;
    if (!PyArg_ParseTuple(args, "Op:pack_ints", &obj, &offset))
        return NULL;
    Py_buffer view;
    Py_ssize_t n;
    if (get_words(obj, &view, &n) < 0)
        return NULL;
    if (n == 0) {
        PyBuffer_Release(&view);
        return PyBytes_FromStringAndSize(NULL, 0);
    }
    const unsigned char *in = view.buf;
    int64_t first = (int64_t)load_u64(in);
    /* q: the deltas, then their quotients by the step, then the stored u64 values. */
    uint64_t *q = PyMem_Malloc((size_t)(n > 1 ? n - 1 : 1) * sizeof(uint64_t));
    if (q == NULL) {
        PyBuffer_Release(&view);
        return PyErr_NoMemory();
    }
    int64_t smallest = 0;
    uint64_t step = 0;
    int64_t prev = first;
    for (Py_ssize_t i = 0; i < n - 1; i++) {
        int64_t w = (int64_t)load_u64(in + 8 * (i + 1));
        int64_t d = wrap_sub(w, prev);
        prev = w;
        q[i] = (uint64_t)d;
        if (i == 0 || d < smallest)
            smallest = d;
        /* |d| as u64: 2^63 for -2^63, which numpy's gcd cannot take (the Python path
         * then uses math.gcd, which gives the same). */
        step = gcd_u64(step, d < 0 ? 0 - (uint64_t)d : (uint64_t)d);
    }
    PyBuffer_Release(&view);
    if (step > (uint64_t)INT64_MAX) /* every delta is 0 or -2^63: keep them whole */
        step = 1;
    int64_t base = 0;
    if (step > 1) { /* exact: the step divides every delta */
        for (Py_ssize_t i = 0; i < n - 1; i++)
            q[i] = (uint64_t)((int64_t)q[i] / (int64_t)step);
    }
    if (offset && n > 1) {
        if (step == 1) {
            base = smallest;
        } else {
            base = (int64_t)q[0];
            for (Py_ssize_t i = 1; i < n - 1; i++)
                if ((int64_t)q[i] < base)
                    base = (int64_t)q[i];
        }
    }
    uint64_t top = 0;
    for (Py_ssize_t i = 0; i < n - 1; i++) {
        q[i] = offset ? q[i] - (uint64_t)base : zigzag((int64_t)q[i]);
        if (q[i] > top)
            top = q[i];
    }
    int width = 0;
    while (width < 8 && (top >> (8 * width)))
        width++;
    /* header: "<qQqB" (first, step, base, width) with offset, else "<qQB" */
    Py_ssize_t head = offset ? 25 : 17;
    PyObject *result = PyBytes_FromStringAndSize(NULL, head + (Py_ssize_t)width * (n - 1));
    if (result == NULL) {
        PyMem_Free(q);
        return NULL;
    }
    unsigned char *out = (unsigned char *)PyBytes_AS_STRING(result);
    out = store_u64(out, (uint64_t)first);
    out = store_u64(out, step);
    if (offset)
        out = store_u64(out, (uint64_t)base);
    *out++ = (unsigned char)width;
    write_planes(out, q, n - 1, width);
    PyMem_Free(q);
    return result;
}

/* frexp's exponent of |v| as a double: the bits a delta needs, the cost that ranks the
 * orders. The same integers as numpy's frexp(abs(v.astype(float64)))[1] in the Python
 * path, summed exactly. */
static long bits_of(int64_t v)
{
    int e = 0;
    frexp(fabs((double)v), &e);
    return e;
}

static PyObject *float_planes(PyObject *self, PyObject *args)
{
    PyObject *obj;
    Py_ssize_t k, n;
    if (!PyArg_ParseTuple(args, "Onn:float_planes", &obj, &k, &n))
        return NULL;
    if (k < 0 || n < 0) {
        PyErr_SetString(PyExc_ValueError, "float_planes needs k >= 0 rows of n >= 0 values");
        return NULL;
    }
    Py_buffer view;
    Py_ssize_t count;
    if (get_words(obj, &view, &count) < 0)
        return NULL;
    /* n bounded too: the four levels of a row take 32 * n bytes, even when k is 0 */
    if (n > PY_SSIZE_T_MAX / 32 || (n > 0 && k > PY_SSIZE_T_MAX / 8 / n) || count != k * n) {
        PyBuffer_Release(&view);
        PyErr_SetString(PyExc_ValueError, "float_planes needs a buffer of k * n i64 values");
        return NULL;
    }
    /* The result objects first: nothing after them can run Python code. */
    PyObject *orders = PyList_New(k);
    PyObject *planes = orders ? PyBytes_FromStringAndSize(NULL, 8 * k * n) : NULL;
    int64_t *level = PyMem_Malloc((size_t)(TOP_ORDER + 1) * (size_t)(n ? n : 1) * sizeof(int64_t));
    uint64_t *z = PyMem_Malloc((size_t)(n ? n : 1) * sizeof(uint64_t));
    if (planes == NULL || level == NULL || z == NULL) {
        PyBuffer_Release(&view);
        Py_XDECREF(orders);
        Py_XDECREF(planes);
        PyMem_Free(level);
        PyMem_Free(z);
        return PyErr_NoMemory();
    }
    const unsigned char *in = view.buf;
    unsigned char *out = (unsigned char *)PyBytes_AS_STRING(planes);
    for (Py_ssize_t j = 0; j < k; j++) {
        /* level r: the r-th repeated difference, the row's first value kept */
        for (Py_ssize_t i = 0; i < n; i++)
            level[i] = (int64_t)load_u64(in + 8 * (j * n + i));
        for (int r = 1; r <= TOP_ORDER; r++) {
            int64_t *up = level + (r - 1) * n, *at = level + r * n;
            if (n)
                at[0] = level[0];
            for (Py_ssize_t i = 1; i < n; i++)
                at[i] = wrap_sub(up[i], up[i - 1]);
        }
        int order = 2; /* too few values to rank */
        if (n > TOP_ORDER) {
            Py_ssize_t stride = n / ORDER_SAMPLES > 1 ? n / ORDER_SAMPLES : 1;
            long long best = 0;
            for (int r = 1; r <= TOP_ORDER; r++) {
                long long cost = 0;
                for (Py_ssize_t i = TOP_ORDER; i < n; i += stride)
                    cost += bits_of(level[r * n + i]);
                if (r == 1 || cost < best) { /* ties: the lowest order, as argmin */
                    best = cost;
                    order = r;
                }
            }
        }
        for (Py_ssize_t i = 0; i < n; i++)
            z[i] = zigzag(level[order * n + i]);
        write_planes(out + 8 * n * j, z, n, 8);
        /* 1..3 are CPython's cached small ints: PyLong_FromLong allocates nothing, cannot fail */
        PyList_SET_ITEM(orders, j, PyLong_FromLong(order));
    }
    PyBuffer_Release(&view);
    PyMem_Free(level);
    PyMem_Free(z);
    PyObject *result = PyTuple_Pack(2, orders, planes);
    Py_DECREF(orders);
    Py_DECREF(planes);
    return result;
}

static PyMethodDef methods[] = {
    {"pack_ints", pack_ints, METH_VARARGS, "packed(n), or offset(n), of a buffer of i64 values, header included."},
    {"float_planes", float_planes, METH_VARARGS, "(orders, planes) of k rows of n f64 bits: FLOAT_DELTA's data."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_planes", NULL, -1, methods};

PyMODINIT_FUNC PyInit__planes(void)
{
    return PyModule_Create(&module);
}
