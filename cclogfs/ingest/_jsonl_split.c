/* The compiled JSONL splitter (issue 14), optional: setup.py builds it where a C
 * compiler is, and cclogfs/ingest/jsonl.py reads every line in Python without it.
 *
 * split_lines(lines: list[bytes], message_type) -> list, one item per line: a
 * `message_type` (a tuple subclass, SourceMessage) of (topic, stamp_ns, msg text, "") for
 * a line in the canonical layout `{"topic": "T", "stamp_ns": N, "msg": {...}}` (its line
 * ending allowed) whose message is JSON, or None for any other line, which the caller
 * reads in Python: that path decides, and names the errors.
 *
 * A line is taken only when Python's `json` would take it with the same result: the msg
 * is checked against json's grammar minus NaN/Infinity (RFC 8259), at most 512 levels
 * deep (json's own limit is Python's recursion limit), every string's UTF-8 checked as
 * Python's strict decoder does (the decode that follows checks it again). Anything else is
 * None, never an answer: being stricter than json costs only speed.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

typedef const unsigned char *P;

#define MAX_DEPTH 512

static int is_hex(unsigned c)
{
    return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F');
}

static P skip_ws(P p, P e)
{
    while (p < e && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r'))
        p++;
    return p;
}

/* n continuation bytes (10xxxxxx) at p. */
static int continuation(P p, P e, int n)
{
    if (e - p < n)
        return 0;
    for (int i = 0; i < n; i++)
        if ((p[i] & 0xC0) != 0x80)
            return 0;
    return 1;
}

/* One UTF-8 sequence that starts with a byte >= 0x80, as Python's strict decoder takes
 * it (no overlong forms, no surrogates, nothing above U+10FFFF): its end, or NULL. */
static P utf8_char(P p, P e)
{
    unsigned c = *p;
    if (c >= 0xC2 && c <= 0xDF)
        return continuation(p + 1, e, 1) ? p + 2 : NULL;
    if (c >= 0xE0 && c <= 0xEF) {
        if (!continuation(p + 1, e, 2) || (c == 0xE0 && p[1] < 0xA0) || (c == 0xED && p[1] > 0x9F))
            return NULL;
        return p + 3;
    }
    if (c >= 0xF0 && c <= 0xF4) {
        if (!continuation(p + 1, e, 3) || (c == 0xF0 && p[1] < 0x90) || (c == 0xF4 && p[1] > 0x8F))
            return NULL;
        return p + 4;
    }
    return NULL;
}

/* A JSON string at p (its opening quote): the byte after its closing quote, or NULL.
 * As json reads it in strict mode: no control characters, only its escapes (\uXXXX with
 * any four hex digits, lone surrogates included, as json takes them). */
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
            c = *p;
            if (c == 'u') {
                if (e - p < 5 || !is_hex(p[1]) || !is_hex(p[2]) || !is_hex(p[3]) || !is_hex(p[4]))
                    return NULL;
                p += 5;
            } else if (c == '"' || c == '\\' || c == '/' || c == 'b' || c == 'f' || c == 'n' || c == 'r' || c == 't') {
                p++;
            } else
                return NULL;
        } else if (c < 0x80) {
            p++;
        } else if ((p = utf8_char(p, e)) == NULL)
            return NULL;
    }
    return NULL;
}

static P digits(P p, P e)
{
    while (p < e && *p >= '0' && *p <= '9')
        p++;
    return p;
}

/* A JSON number (json's NUMBER_RE: -?(0|[1-9]\d*)(\.\d+)?([eE][-+]?\d+)?): its end or NULL. */
static P number(P p, P e)
{
    if (p < e && *p == '-')
        p++;
    if (p >= e || *p < '0' || *p > '9')
        return NULL;
    P whole = p;
    p = *p == '0' ? p + 1 : digits(p, e);
    /* json reads an integer by int(), which refuses more than sys.get_int_max_str_digits()
     * digits (4300 by default, at least 640 when set): longer ones go to the Python path,
     * which asks json itself. */
    if (p - whole > 640)
        return NULL;
    if (p < e && *p == '.') {
        P start = ++p;
        if ((p = digits(p, e)) == start)
            return NULL;
    }
    if (p < e && (*p == 'e' || *p == 'E')) {
        p++;
        if (p < e && (*p == '+' || *p == '-'))
            p++;
        P start = p;
        if ((p = digits(p, e)) == start)
            return NULL;
    }
    return p;
}

static P value(P p, P e, int depth);

/* The members of an object or the items of an array, p just after its '{' or '['. */
static P container(P p, P e, int depth, int object)
{
    unsigned char close = object ? '}' : ']';
    p = skip_ws(p, e);
    if (p < e && *p == close)
        return p + 1;
    for (;;) {
        if (object) {
            if ((p = string(p, e)) == NULL)
                return NULL;
            p = skip_ws(p, e);
            if (p >= e || *p != ':')
                return NULL;
            p = skip_ws(p + 1, e);
        }
        if ((p = value(p, e, depth + 1)) == NULL)
            return NULL;
        p = skip_ws(p, e);
        if (p < e && *p == ',') {
            p = skip_ws(p + 1, e);
            continue;
        }
        return p < e && *p == close ? p + 1 : NULL;
    }
}

/* One JSON value at p (no whitespace before it): its end, or NULL. */
static P value(P p, P e, int depth)
{
    if (p >= e || depth >= MAX_DEPTH) /* depth 0 is the msg object: 512 levels in all */
        return NULL;
    switch (*p) {
    case '{':
        return container(p + 1, e, depth, 1);
    case '[':
        return container(p + 1, e, depth, 0);
    case '"':
        return string(p, e);
    case 't':
        return e - p >= 4 && !memcmp(p, "true", 4) ? p + 4 : NULL;
    case 'n':
        return e - p >= 4 && !memcmp(p, "null", 4) ? p + 4 : NULL;
    case 'f':
        return e - p >= 5 && !memcmp(p, "false", 5) ? p + 5 : NULL;
    default:
        return number(p, e);
    }
}

/* The head of the canonical layout, as cclogfs/jsontext/lines.py's _HEAD. */
#define HEAD_TOPIC "{\"topic\": \""
#define HEAD_STAMP "\", \"stamp_ns\": "
#define HEAD_MSG ", \"msg\": "

/* The stamp at *p (0|-?[1-9][0-9]{0,18}, within int64): 1 and *p moved past it, else 0.
 * -2^63 itself is left to Python (its magnitude does not fit in int64). */
static int stamp(P *pp, P e, long long *out)
{
    P p = *pp;
    int negative = p < e && *p == '-';
    P first = p + negative, q = first;
    unsigned long long n = 0;
    while (q < e && *q >= '0' && *q <= '9' && q - first < 19)
        n = n * 10 + (unsigned)(*q++ - '0'); /* 19 digits fit in 64 unsigned bits */
    if (q == first || (q < e && *q >= '0' && *q <= '9') || n > INT64_MAX)
        return 0;
    if (*first == '0' && (q - first > 1 || negative))
        return 0;
    *out = negative ? -(long long)n : (long long)n;
    *pp = q;
    return 1;
}

/* The last topic decoded, so that a run of lines on one topic shares one str (a
 * decode and an allocation fewer a line; the dict lookups and compares that follow
 * find the same object). */
typedef struct {
    PyObject *text; /* a reference of its own, released by split_lines */
    P bytes;        /* its UTF-8 bytes, in the line it came from (the caller's list holds it) */
    Py_ssize_t size;
} LastTopic;

/* The topic's str, a new reference, or NULL with the decode's error set. */
static PyObject *topic_text(P topic, Py_ssize_t size, LastTopic *last)
{
    if (last->text != NULL && size == last->size && !memcmp(topic, last->bytes, size)) {
        Py_INCREF(last->text);
        return last->text;
    }
    PyObject *t = PyUnicode_DecodeUTF8((const char *)topic, size, "strict");
    if (t != NULL) {
        Py_INCREF(t);
        Py_XSETREF(last->text, t);
        last->bytes = topic;
        last->size = size;
    }
    return t;
}

/* The message of one line, a new reference: a message_type, or None (not settled here). */
static PyObject *split_line(P s, P e, PyTypeObject *message_type, PyObject *no_msgtype, LastTopic *last)
{
    if (e > s && e[-1] == '\n') { /* the line endings lines.py's _FAST_LINE allows */
        e--;
        if (e > s && e[-1] == '\r')
            e--;
    }
    size_t head = sizeof(HEAD_TOPIC) - 1;
    if ((size_t)(e - s) < head || memcmp(s, HEAD_TOPIC, head))
        Py_RETURN_NONE;
    P topic = s + head, p = topic;
    while (p < e && *p != '"' && *p != '\\' && *p >= 0x20)
        p++;
    P topic_end = p;
    head = sizeof(HEAD_STAMP) - 1;
    if (p == topic || (size_t)(e - p) < head || memcmp(p, HEAD_STAMP, head))
        Py_RETURN_NONE;
    p += head;
    long long stamp_ns;
    head = sizeof(HEAD_MSG) - 1;
    if (!stamp(&p, e, &stamp_ns) || (size_t)(e - p) < head || memcmp(p, HEAD_MSG, head))
        Py_RETURN_NONE;
    P msg = p + head;
    if (msg >= e || *msg != '{')
        Py_RETURN_NONE;
    P msg_end = value(msg, e, 0);
    if (msg_end == NULL || msg_end + 1 != e || *msg_end != '}')
        Py_RETURN_NONE;
    /* Strict decodes: a topic that is not UTF-8 leaves the line to Python. */
    PyObject *t = topic_text(topic, topic_end - topic, last);
    PyObject *m = t ? PyUnicode_DecodeUTF8((const char *)msg, msg_end - msg, "strict") : NULL;
    PyObject *n = m ? PyLong_FromLongLong(stamp_ns) : NULL;
    /* A tuple subclass with no fields of its own (a NamedTuple): allocated as a tuple. */
    PyObject *out = n ? message_type->tp_alloc(message_type, 4) : NULL;
    if (out == NULL) {
        Py_XDECREF(t);
        Py_XDECREF(m);
        Py_XDECREF(n);
        if (!PyErr_ExceptionMatches(PyExc_UnicodeDecodeError))
            return NULL; /* out of memory: not a verdict on the line */
        PyErr_Clear();
        Py_RETURN_NONE;
    }
    Py_INCREF(no_msgtype);
    PyTuple_SET_ITEM(out, 0, t);
    PyTuple_SET_ITEM(out, 1, n);
    PyTuple_SET_ITEM(out, 2, m);
    PyTuple_SET_ITEM(out, 3, no_msgtype);
    return out;
}

static PyObject *split_lines(PyObject *Py_UNUSED(self), PyObject *args)
{
    PyObject *lines;
    PyTypeObject *message_type;
    if (!PyArg_ParseTuple(args, "O!O!:split_lines", &PyList_Type, &lines, &PyType_Type, &message_type))
        return NULL;
    if (!PyType_IsSubtype(message_type, &PyTuple_Type) || message_type->tp_itemsize != sizeof(PyObject *))
        return PyErr_Format(PyExc_TypeError, "split_lines: the message type must be a tuple subclass");
    PyObject *no_msgtype = PyUnicode_FromString("");
    Py_ssize_t count = PyList_GET_SIZE(lines);
    PyObject *out = no_msgtype ? PyList_New(count) : NULL;
    LastTopic last = {NULL, NULL, 0};
    for (Py_ssize_t i = 0; out != NULL && i < count; i++) {
        PyObject *line = PyList_GET_ITEM(lines, i);
        if (!PyBytes_Check(line)) {
            PyErr_Format(PyExc_TypeError, "split_lines takes a list of bytes, not %.80s", Py_TYPE(line)->tp_name);
            Py_CLEAR(out);
            break;
        }
        P s = (P)PyBytes_AS_STRING(line);
        PyObject *message = split_line(s, s + PyBytes_GET_SIZE(line), message_type, no_msgtype, &last);
        if (message == NULL)
            Py_CLEAR(out);
        else
            PyList_SET_ITEM(out, i, message);
    }
    Py_XDECREF(no_msgtype);
    Py_XDECREF(last.text);
    return out;
}

static PyMethodDef methods[] = {
    {"split_lines", split_lines, METH_VARARGS, "Messages of the lines in the canonical layout, None for the others."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_jsonl_split", NULL, -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__jsonl_split(void)
{
    return PyModule_Create(&module);
}
