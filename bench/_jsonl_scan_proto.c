/* PROTOTYPE, not used by cclogfs: what a compiled JSONL splitter would cost (issue 14).
 * Built and timed by bench/jsonl_scan_proto.py; see docs/MEASURED.md.
 *
 * scan(lines: list[bytes]) -> list of (topic, stamp_ns, msg text) or None, one per line:
 * the canonical layout `{"topic": "T", "stamp_ns": N, "msg": {...}}` (line ending
 * allowed), the msg checked against the JSON grammar (RFC 8259, the subset of what
 * Python's json reads: no NaN/Infinity, at most 512 levels) with every string's UTF-8
 * checked as Python's strict decoder does. None: anything else (the caller would take
 * the existing path, which decides).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <ctype.h>
#include <stdint.h>
#include <string.h>

typedef const unsigned char *P;

static P ws(P p, P e)
{
    while (p < e && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r'))
        p++;
    return p;
}

static int cont(P p, P e, int n)
{
    for (int i = 0; i < n; i++)
        if (p + i >= e || (p[i] & 0xC0) != 0x80)
            return 0;
    return 1;
}

static P string(P p, P e)
{
    if (p >= e || *p != '"')
        return NULL;
    for (p++; p < e;) {
        unsigned c = *p;
        if (c == '"')
            return p + 1;
        if (c < 0x20)
            return NULL;
        if (c == '\\') {
            if (++p >= e)
                return NULL;
            if (*p == 'u') {
                for (int i = 1; i <= 4; i++)
                    if (p + i >= e || !isxdigit(p[i]))
                        return NULL;
                p += 5;
            } else if (strchr("\"\\/bfnrt", *p) && *p) {
                p++;
            } else
                return NULL;
        } else if (c < 0x80) {
            p++;
        } else if (c >= 0xC2 && c <= 0xDF) {
            if (!cont(p + 1, e, 1))
                return NULL;
            p += 2;
        } else if (c >= 0xE0 && c <= 0xEF) {
            if (!cont(p + 1, e, 2) || (c == 0xE0 && p[1] < 0xA0) || (c == 0xED && p[1] > 0x9F))
                return NULL;
            p += 3;
        } else if (c >= 0xF0 && c <= 0xF4) {
            if (!cont(p + 1, e, 3) || (c == 0xF0 && p[1] < 0x90) || (c == 0xF4 && p[1] > 0x8F))
                return NULL;
            p += 4;
        } else
            return NULL;
    }
    return NULL;
}

static P number(P p, P e)
{
    if (p < e && *p == '-')
        p++;
    if (p >= e)
        return NULL;
    if (*p == '0')
        p++;
    else if (*p >= '1' && *p <= '9')
        while (p < e && *p >= '0' && *p <= '9')
            p++;
    else
        return NULL;
    if (p < e && *p == '.') {
        P q = ++p;
        while (p < e && *p >= '0' && *p <= '9')
            p++;
        if (p == q)
            return NULL;
    }
    if (p < e && (*p == 'e' || *p == 'E')) {
        p++;
        if (p < e && (*p == '+' || *p == '-'))
            p++;
        P q = p;
        while (p < e && *p >= '0' && *p <= '9')
            p++;
        if (p == q)
            return NULL;
    }
    return p;
}

static P value(P p, P e, int depth)
{
    if (p >= e || depth > 512)
        return NULL;
    if (*p == '{' || *p == '[') {
        unsigned char close = *p == '{' ? '}' : ']';
        int obj = *p == '{';
        p = ws(p + 1, e);
        if (p < e && *p == close)
            return p + 1;
        for (;;) {
            if (obj) {
                if (!(p = string(p, e)))
                    return NULL;
                p = ws(p, e);
                if (p >= e || *p != ':')
                    return NULL;
                p = ws(p + 1, e);
            }
            if (!(p = value(p, e, depth + 1)))
                return NULL;
            p = ws(p, e);
            if (p < e && *p == ',') {
                p = ws(p + 1, e);
                continue;
            }
            return p < e && *p == close ? p + 1 : NULL;
        }
    }
    if (*p == '"')
        return string(p, e);
    if (e - p >= 4 && (!memcmp(p, "true", 4) || !memcmp(p, "null", 4)))
        return p + 4;
    if (e - p >= 5 && !memcmp(p, "false", 5))
        return p + 5;
    return number(p, e);
}

#define HEAD1 "{\"topic\": \""
#define HEAD2 "\", \"stamp_ns\": "
#define HEAD3 ", \"msg\": "

static PyObject *one(P s, P e)
{
    if (e > s && e[-1] == '\n')
        e--;
    if (e > s && e[-1] == '\r')
        e--;
    if (e - s < 11 || memcmp(s, HEAD1, 11))
        Py_RETURN_NONE;
    P t = s + 11, p = t;
    while (p < e && *p != '"' && *p != '\\' && *p >= 0x20)
        p++;
    if (p == t || e - p < 15 || memcmp(p, HEAD2, 15))
        Py_RETURN_NONE;
    P te = p;
    p += 15;
    int neg = p < e && *p == '-';
    P d = p + neg, q = d;
    unsigned long long digits = 0;
    while (q < e && *q >= '0' && *q <= '9' && q - d < 19)
        digits = digits * 10 + (unsigned)(*q++ - '0');  /* 19 digits fit in 64 unsigned bits */
    if (q == d || (*d == '0' && (q - d > 1 || neg)) || (q < e && *q >= '0' && *q <= '9') || digits > INT64_MAX)
        Py_RETURN_NONE;
    long long stamp = neg ? -(long long)digits : (long long)digits;
    if (e - q < 9 || memcmp(q, HEAD3, 9))
        Py_RETURN_NONE;
    P m = q + 9;
    if (m >= e || *m != '{')
        Py_RETURN_NONE;
    P me = value(m, e, 0);
    if (me == NULL || me + 1 != e || *me != '}')
        Py_RETURN_NONE;
    PyObject *topic = PyUnicode_DecodeUTF8((const char *)t, te - t, "strict");
    PyObject *msg = topic ? PyUnicode_DecodeUTF8((const char *)m, me - m, "strict") : NULL;
    PyObject *out = msg ? Py_BuildValue("(NLN)", topic, stamp, msg) : NULL;
    if (out == NULL) {
        Py_XDECREF(topic);
        PyErr_Clear();
        Py_RETURN_NONE;
    }
    return out;
}

static PyObject *scan(PyObject *Py_UNUSED(self), PyObject *lines)
{
    if (!PyList_Check(lines))
        return PyErr_Format(PyExc_TypeError, "scan takes a list of bytes");
    Py_ssize_t n = PyList_GET_SIZE(lines);
    PyObject *out = PyList_New(n);
    for (Py_ssize_t i = 0; out && i < n; i++) {
        PyObject *line = PyList_GET_ITEM(lines, i);
        if (!PyBytes_Check(line)) {
            Py_CLEAR(out);
            return PyErr_Format(PyExc_TypeError, "scan takes a list of bytes");
        }
        P s = (P)PyBytes_AS_STRING(line);
        PyList_SET_ITEM(out, i, one(s, s + PyBytes_GET_SIZE(line)));
    }
    return out;
}

static PyMethodDef methods[] = {{"scan", scan, METH_O, NULL}, {NULL, NULL, 0, NULL}};
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_jsonl_scan_proto", NULL, -1, methods, NULL, NULL, NULL, NULL};
PyMODINIT_FUNC PyInit__jsonl_scan_proto(void) { return PyModule_Create(&module); }
