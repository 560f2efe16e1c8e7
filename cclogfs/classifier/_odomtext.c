/* The stamp and 13 values of a nav_msgs/Odometry in rosbridge JSON text: features._ODOM_TEXT
 * in C (issue 14: the regex and float() of its groups were half of smart logging's time).
 *
 * odom_fields(text) -> (stamp_ns, (13 floats)) exactly as features.odom_row's regex path
 * gives it: int(sec) * 10**9 + int(nanosec), and float() of each captured number (by
 * PyOS_string_to_double, the function float() itself calls, so the same double). The
 * layout is the one json.dumps gives (fields in definition order, ROS 1 headers with a
 * seq):
 *   {"header": {["seq": D, ]"stamp": {"sec"|"secs": D, "nanosec"|"nsecs": D},
 *   "frame_id": S}, "child_frame_id": S, "pose": {"pose": {"position": XYZ,
 *   "orientation": {"x": N, "y": N, "z": N, "w": N}}, "covariance": C}, "twist":
 *   {"twist": {"linear": XYZ, "angular": XYZ}, "covariance": C}}
 * with D [0-9]+, S a JSON string token "[^"\\]*(?:\\.[^"\\]*)*" (the regex's "." after a
 * backslash: any character but a newline), N a JSON number, NaN or -?Infinity, C "[" then
 * anything but "]" then "]".
 *
 * None when the text does not have that layout, or has it with a stamp too large for 64
 * bits, or is not one byte per character: the caller then takes the Python path, which
 * gives the same answer (or its error). Optional: cclogfs works without it.
 *
 * odom_rows(list of texts) -> (rows, flagged): odom_fields of each, and the positions
 * whose row is None or holds a NaN or infinite value.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <float.h>
#include <math.h>
#include <string.h>

typedef struct {
    const unsigned char *s;
    Py_ssize_t pos, n;
} Cursor;

/* Consume the literal lit if it comes next. */
static int lit(Cursor *c, const char *lit)
{
    size_t k = strlen(lit);
    if ((size_t)(c->n - c->pos) < k || memcmp(c->s + c->pos, lit, k) != 0)
        return 0;
    c->pos += (Py_ssize_t)k;
    return 1;
}

/* [0-9]+ as a value; 0 when absent or of more than 18 significant digits (left to Python). */
static int digits(Cursor *c, long long *out)
{
    Py_ssize_t start = c->pos;
    while (c->pos < c->n && c->s[c->pos] >= '0' && c->s[c->pos] <= '9')
        c->pos++;
    if (c->pos == start)
        return 0;
    while (start < c->pos - 1 && c->s[start] == '0')
        start++;
    if (c->pos - start > 18)
        return 0;
    long long v = 0;
    for (Py_ssize_t i = start; i < c->pos; i++)
        v = v * 10 + (c->s[i] - '0');
    *out = v;
    return 1;
}

static int string_token(Cursor *c)
{
    const unsigned char *s = c->s;
    Py_ssize_t i = c->pos, n = c->n;
    if (i >= n || s[i] != '"')
        return 0;
    for (i++; i < n; i++) {
        if (s[i] == '"') {
            c->pos = i + 1;
            return 1;
        }
        if (s[i] == '\\' && (++i >= n || s[i] == '\n'))
            return 0;
    }
    return 0;
}

static int covariance(Cursor *c)
{
    if (c->pos >= c->n || c->s[c->pos] != '[')
        return 0;
    const unsigned char *end = memchr(c->s + c->pos + 1, ']', (size_t)(c->n - c->pos - 1));
    if (end == NULL)
        return 0;
    c->pos = end - c->s + 1;
    return 1;
}

static int is_digit(const Cursor *c, Py_ssize_t i)
{
    return i < c->n && c->s[i] >= '0' && c->s[i] <= '9';
}

#if LDBL_MANT_DIG == 64 && FLT_RADIX == 2
/* Exact powers of ten in x87 extended precision (64-bit significand: 5^27 < 2^64). */
static const long double POW10[28] = {1e0L,  1e1L,  1e2L,  1e3L,  1e4L,  1e5L,  1e6L,  1e7L,  1e8L,  1e9L,
                                      1e10L, 1e11L, 1e12L, 1e13L, 1e14L, 1e15L, 1e16L, 1e17L, 1e18L, 1e19L,
                                      1e20L, 1e21L, 1e22L, 1e23L, 1e24L, 1e25L, 1e26L, 1e27L};

/* The double nearest digits * 10^exp10 (the sign apart), as float() gives it, or 0 with
 * *ok unset when this quick way cannot tell. digits < 2^64 and 10^|exp10| (|exp10| <= 27)
 * are exact in extended precision, so the product or quotient q is rounded once, to 64
 * bits; rounding q to 53 bits then gives the correctly rounded double unless q lies
 * exactly halfway between two doubles (its 11 low bits 10000000000), where the true value
 * may have been on either side: those few go to the slow path. Results stay far from the
 * subnormal range (|exp10| <= 27, digits < 10^19). */
static double quick_decimal(unsigned long long digits, int exp10, int *ok)
{
    *ok = 0;
    if (exp10 < -27 || exp10 > 27)
        return 0.0;
    if (digits == 0) {
        *ok = 1;
        return 0.0;
    }
    long double q = exp10 < 0 ? (long double)digits / POW10[-exp10] : (long double)digits * POW10[exp10];
    unsigned long long mant;
    memcpy(&mant, &q, sizeof mant); /* x87 layout: the 64-bit significand comes first */
    if ((mant & 0x7FF) == 0x400)
        return 0.0;
    *ok = 1;
    return (double)q;
}
#else
static double quick_decimal(unsigned long long digits, int exp10, int *ok)
{
    *ok = 0; /* no x87 extended precision here: always the slow path */
    return 0.0;
}
#endif

/* One number token, converted as float() converts it; 0 when none comes next. */
static int number(Cursor *c, double *out)
{
    Py_ssize_t i = c->pos, start = c->pos;
    int negative = 0, ndigits = 0, exp10 = 0, quick = 1;
    unsigned long long w = 0;
    if (i < c->n && c->s[i] == '-') {
        negative = 1;
        i++;
    }
    if (is_digit(c, i)) {
        /* the significand's digits, leading zeros skipped (at most 19 count: w < 10^19) */
        if (c->s[i] == '0')
            i++;
        else
            for (; is_digit(c, i); i++, ndigits++)
                w = w * 10 + (unsigned long long)(c->s[i] - '0');
        if (i < c->n && c->s[i] == '.' && is_digit(c, i + 1))
            for (i++; is_digit(c, i); i++, exp10--) {
                if (w == 0 && c->s[i] == '0')
                    continue;
                w = w * 10 + (unsigned long long)(c->s[i] - '0');
                ndigits++;
            }
        if (i < c->n && (c->s[i] == 'e' || c->s[i] == 'E')) {
            Py_ssize_t j = i + 1;
            int esign = 1, e = 0;
            if (j < c->n && (c->s[j] == '+' || c->s[j] == '-'))
                esign = c->s[j++] == '-' ? -1 : 1;
            if (is_digit(c, j)) {
                for (i = j; is_digit(c, i); i++)
                    if (e < 10000)
                        e = e * 10 + (c->s[i] - '0');
                exp10 += esign * e;
            }
        }
        if (ndigits > 19)
            quick = 0;
    } else if (c->n - start >= 3 && memcmp(c->s + start, "NaN", 3) == 0) {
        i = start + 3;
        quick = 0;
    } else if (c->n - i >= 8 && memcmp(c->s + i, "Infinity", 8) == 0) {
        i += 8;
        quick = 0;
    } else {
        return 0;
    }
    if (quick) {
        int ok;
        double v = quick_decimal(w, exp10, &ok);
        if (ok) {
            *out = negative ? -v : v;
            c->pos = i;
            return 1;
        }
    }
    /* The slow path: float()'s own conversion. A number is at most a few hundred
     * characters in any sane message; longer ones go to Python. */
    char buf[400];
    Py_ssize_t len = i - start;
    if (len >= (Py_ssize_t)sizeof(buf))
        return 0;
    memcpy(buf, c->s + start, (size_t)len);
    buf[len] = '\0';
    char *end;
    double v = PyOS_string_to_double(buf, &end, NULL);
    if (v == -1.0 && PyErr_Occurred()) {
        PyErr_Clear();
        return 0;
    }
    if (end != buf + len)
        return 0;
    *out = v;
    c->pos = i;
    return 1;
}

/* {"x": N, "y": N, "z": N} into out[0..2] */
static int xyz(Cursor *c, double *out)
{
    return lit(c, "{\"x\": ") && number(c, out) && lit(c, ", \"y\": ") && number(c, out + 1) &&
           lit(c, ", \"z\": ") && number(c, out + 2) && lit(c, "}");
}

static int parse(Cursor *c, long long *sec, long long *nsec, double *v)
{
    long long seq;
    if (!lit(c, "{\"header\": {"))
        return 0;
    if (lit(c, "\"seq\": ") && !(digits(c, &seq) && lit(c, ", ")))
        return 0;
    if (!(lit(c, "\"stamp\": {\"") && (lit(c, "secs") || lit(c, "sec")) && lit(c, "\": ") && digits(c, sec) &&
          lit(c, ", \"") && (lit(c, "nanosec") || lit(c, "nsecs")) && lit(c, "\": ") && digits(c, nsec) &&
          lit(c, "}, \"frame_id\": ") && string_token(c) && lit(c, "}, \"child_frame_id\": ") &&
          string_token(c)))
        return 0;
    return lit(c, ", \"pose\": {\"pose\": {\"position\": ") && xyz(c, v) && lit(c, ", \"orientation\": {\"x\": ") &&
           number(c, v + 3) && lit(c, ", \"y\": ") && number(c, v + 4) && lit(c, ", \"z\": ") &&
           number(c, v + 5) && lit(c, ", \"w\": ") && number(c, v + 6) && lit(c, "}}, \"covariance\": ") &&
           covariance(c) && lit(c, "}, \"twist\": {\"twist\": {\"linear\": ") && xyz(c, v + 7) &&
           lit(c, ", \"angular\": ") && xyz(c, v + 10) && lit(c, "}, \"covariance\": ") && covariance(c) &&
           lit(c, "}}") && c->pos == c->n;
}

/* (stamp_ns, row) of one text, or None (a new reference either way); *finite unset when
 * the row holds a NaN or infinite value. NULL with an exception only when out of memory. */
static PyObject *read_one(PyObject *text, int *finite)
{
    *finite = 1;
    if (!PyUnicode_Check(text) || PyUnicode_KIND(text) != PyUnicode_1BYTE_KIND)
        Py_RETURN_NONE;
    Cursor c = {PyUnicode_1BYTE_DATA(text), 0, PyUnicode_GET_LENGTH(text)};
    long long sec, nsec;
    double v[13];
    /* 9,223,372,035 s (year 2262) is the last second whose stamp fits in int64 */
    if (!parse(&c, &sec, &nsec, v) || sec > 9223372035LL || nsec > 9223372036854775807LL - sec * 1000000000LL)
        Py_RETURN_NONE;
    PyObject *row = PyTuple_New(13);
    if (row == NULL)
        return NULL;
    for (int k = 0; k < 13; k++) {
        PyObject *f = PyFloat_FromDouble(v[k]);
        if (f == NULL) {
            Py_DECREF(row);
            return NULL;
        }
        PyTuple_SET_ITEM(row, k, f);
        *finite &= isfinite(v[k]) != 0;
    }
    PyObject *stamp = PyLong_FromLongLong(sec * 1000000000LL + nsec);
    if (stamp == NULL) {
        Py_DECREF(row);
        return NULL;
    }
    return Py_BuildValue("(NN)", stamp, row);
}

static PyObject *odom_fields(PyObject *self, PyObject *text)
{
    int finite;
    return read_one(text, &finite);
}

/* odom_rows(texts) -> (rows, flagged): odom_fields of each text of the list, and the
 * positions whose row is None or holds a NaN or infinite value, in order. The flags let
 * the caller (pipeline.KeepUnscored, issue 14) look at those few rows in Python instead of
 * checking every row's 13 values there. */
static PyObject *odom_rows(PyObject *self, PyObject *texts)
{
    if (!PyList_Check(texts)) {
        PyErr_SetString(PyExc_TypeError, "odom_rows takes a list of str");
        return NULL;
    }
    Py_ssize_t n = PyList_GET_SIZE(texts);
    PyObject *rows = PyList_New(n), *flagged = PyList_New(0);
    if (rows == NULL || flagged == NULL)
        goto fail;
    for (Py_ssize_t i = 0; i < n; i++) {
        int finite;
        PyObject *got = read_one(PyList_GET_ITEM(texts, i), &finite);
        if (got == NULL)
            goto fail;
        PyList_SET_ITEM(rows, i, got);
        if (got == Py_None || !finite) {
            PyObject *at = PyLong_FromSsize_t(i);
            if (at == NULL || PyList_Append(flagged, at) < 0) {
                Py_XDECREF(at);
                goto fail;
            }
            Py_DECREF(at);
        }
    }
    return Py_BuildValue("(NN)", rows, flagged);
fail:
    Py_XDECREF(rows);
    Py_XDECREF(flagged);
    return NULL;
}

static PyMethodDef methods[] = {
    {"odom_fields", odom_fields, METH_O, "(stamp_ns, 13 floats) of an Odometry's JSON text, or None."},
    {"odom_rows", odom_rows, METH_O, "(odom_fields of each text of a list, positions of None or non-finite rows)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_odomtext", NULL, -1, methods};

PyMODINIT_FUNC PyInit__odomtext(void)
{
    return PyModule_Create(&module);
}
