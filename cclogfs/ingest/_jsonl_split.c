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
#if defined(__GNUC__) && defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    /* Eight bytes at a time (a measurement has 15-17 digits): a byte is a digit when its
     * high nibble is 3 and adding 6 leaves it 3. A carry out of a byte only reaches the
     * bytes after it, which the first byte flagged ends the digits before. */
    const uint64_t high = 0xF0F0F0F0F0F0F0F0u, threes = 0x3030303030303030u, sixes = 0x0606060606060606u;
    while (e - p >= 8) {
        uint64_t x;
        memcpy(&x, p, 8);
        uint64_t other = ((x & high) ^ threes) | (((x + sixes) & high) ^ threes);
        if (other)
            return p + (__builtin_ctzll(other) >> 3);
        p += 8;
    }
#endif
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

/* A value that is no object or array (a string, number, true, false or null): its end,
 * or NULL. */
static P scalar(P p, P e)
{
    switch (p < e ? *p : 0) {
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

/* Where the scalars of a message lie, as offsets from its start: what makes a checked
 * message a template (below). The arrays grow as scalars are added, up to MAX_SCALARS;
 * count -1: more, or no memory for them (then no template: it only saves time). */
#define MAX_SCALARS (1 << 16)

typedef struct {
    int count, room;
    Py_ssize_t *start, *end; /* `room` each, one block */
} Scalars;

static void add_scalar(Scalars *scalars, P msg, P start, P end)
{
    if (scalars->count < 0)
        return;
    if (scalars->count == scalars->room) {
        int room = scalars->room ? 2 * scalars->room : 64;
        Py_ssize_t *block = room <= MAX_SCALARS ? PyMem_Realloc(scalars->start, 2 * room * sizeof(Py_ssize_t)) : NULL;
        if (block == NULL) {
            scalars->count = -1;
            return;
        }
        memmove(block + room, block + scalars->room, scalars->count * sizeof(Py_ssize_t)); /* the ends */
        scalars->start = block;
        scalars->end = block + room;
        scalars->room = room;
    }
    scalars->start[scalars->count] = start - msg;
    scalars->end[scalars->count++] = end - msg;
}

static P value(P p, P e, int depth, Scalars *rec, P msg);

/* The members of an object or the items of an array, p just after its '{' or '['. */
static P container(P p, P e, int depth, int object, Scalars *rec, P msg)
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
        if ((p = value(p, e, depth + 1, rec, msg)) == NULL)
            return NULL;
        p = skip_ws(p, e);
        if (p < e && *p == ',') {
            p = skip_ws(p + 1, e);
            continue;
        }
        return p < e && *p == close ? p + 1 : NULL;
    }
}

/* One JSON value at p (no whitespace before it): its end, or NULL. With `rec`, each
 * scalar read is added to it, as offsets from `msg`. */
static P value(P p, P e, int depth, Scalars *rec, P msg)
{
    if (p >= e || depth >= MAX_DEPTH) /* depth 0 is the msg object: 512 levels in all */
        return NULL;
    if (*p == '{' || *p == '[')
        return container(p + 1, e, depth, *p == '{', rec, msg);
    P end = scalar(p, e);
    if (end != NULL && rec != NULL)
        add_scalar(rec, msg, p, end);
    return end;
}

/* A template: the last message of a topic that the grammar check took whole, with
 * where its scalars (strings that are not keys, numbers, true, false, null) lie. A
 * message of the same topic whose bytes are the template's outside those scalars, with
 * a scalar at each, is JSON as well: a scalar is a value wherever one stands, and the
 * rest is the template's, text and nesting. It is also valid UTF-8: the scalars begin
 * and end at ASCII bytes, so no UTF-8 sequence of the template is cut, and string()
 * checks theirs. Checking that compares the text between the scalars and reads the
 * scalars alone: on odometry, two thirds of the grammar check's work less (issue 14).
 * A message that does not match (another layout) takes the grammar check and becomes
 * its topic's template when it passes; a topic whose messages keep changing layout is
 * tried against its template only now and then. A topic has a slot by the hash of its
 * name (another topic with the same slot takes it over). Templates point into the
 * lines of one call of split_lines, which holds them. */
#define TEMPLATES 64
#define MISSES 4 /* in a row, after which a template is tried once in RETRY messages */
#define RETRY 16

typedef struct {
    P topic, msg; /* NULL: an empty slot */
    Py_ssize_t topic_size, msg_size;
    Scalars scalars;
    int misses; /* messages in a row that took the grammar check (tried and missed, or not tried) */
} Template;

/* Whether a and b hold the same n bytes: most texts between scalars are a few bytes
 * (", "), shorter than a call of memcmp takes to set up. */
static int same(P a, P b, Py_ssize_t n)
{
    if (n > 16)
        return !memcmp(a, b, n);
    for (Py_ssize_t i = 0; i < n; i++)
        if (a[i] != b[i])
            return 0;
    return 1;
}

/* Whether the message [msg, e) matches the template (see Template). */
static int matches(const Template *t, P msg, P e)
{
    const Scalars *sc = &t->scalars;
    P q = msg;
    Py_ssize_t done = 0; /* the template's offset past its last scalar read */
    for (int i = 0; i < sc->count; i++) {
        Py_ssize_t text = sc->start[i] - done;
        if (e - q < text || !same(q, t->msg + done, text))
            return 0;
        q += text;
        /* A scalar as the template's needs no reading (most of a covariance matrix):
         * the text after it, compared next, starts with white space, a comma, a
         * bracket or a brace, which no scalar goes on with, so it ends there too. */
        Py_ssize_t size = sc->end[i] - sc->start[i];
        if (e - q >= size && same(q, t->msg + sc->start[i], size))
            q += size;
        else if ((q = scalar(q, e)) == NULL)
            return 0;
        done = sc->end[i];
    }
    return e - q == t->msg_size - done && same(q, t->msg + done, e - q);
}

typedef struct {
    Template slot[TEMPLATES];
    Scalars spare; /* what the grammar check records into; swapped into the slot it fills */
} Templates;

/* Whether the message [msg, msg_end) is JSON (an object: the caller checked its first
 * byte): by its topic's template, else by the grammar check, after which it becomes
 * that topic's template. Without templates (ts NULL), by the grammar check alone. */
static int message_is_json(Templates *ts, P topic, Py_ssize_t topic_size, P msg, P msg_end)
{
    if (ts == NULL)
        return value(msg, msg_end, 0, NULL, msg) == msg_end;
    uint32_t hash = 2166136261u; /* FNV-1a */
    for (Py_ssize_t i = 0; i < topic_size; i++)
        hash = (hash ^ topic[i]) * 16777619u;
    Template *t = &ts->slot[hash % TEMPLATES];
    int mine = t->topic != NULL && t->topic_size == topic_size && !memcmp(t->topic, topic, topic_size);
    if (mine && t->scalars.count >= 0 && (t->misses < MISSES || t->misses % RETRY == 0)) {
        if (matches(t, msg, msg_end)) {
            t->misses = 0;
            return 1;
        }
    }
    ts->spare.count = 0;
    if (value(msg, msg_end, 0, &ts->spare, msg) != msg_end)
        return 0;
    t->misses = mine ? t->misses + 1 : 0;
    Scalars taken = t->scalars;
    t->scalars = ts->spare;
    ts->spare = taken;
    t->topic = topic;
    t->topic_size = topic_size;
    t->msg = msg;
    t->msg_size = msg_end - msg;
    return 1;
}

static void free_templates(Templates *ts)
{
    if (ts == NULL)
        return;
    for (int i = 0; i < TEMPLATES; i++)
        PyMem_Free(ts->slot[i].scalars.start);
    PyMem_Free(ts->spare.start);
    PyMem_Free(ts);
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
    P bytes;        /* its UTF-8 bytes, in the line it came from (split_lines holds it) */
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
static PyObject *split_line(P s, P e, PyTypeObject *message_type, PyObject *no_msgtype, LastTopic *last,
                            Templates *templates)
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
    /* The line ends with the msg and the layout's closing brace. */
    P msg_end = e - 1;
    if (*msg_end != '}' || !message_is_json(templates, topic, topic_end - topic, msg, msg_end))
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
    /* The lines held for the call: the topic cache and the templates point into them,
     * across allocations that may run code (a finalizer changing the caller's list). */
    PyObject *held = PyList_AsTuple(lines);
    PyObject *no_msgtype = held ? PyUnicode_FromString("") : NULL;
    Py_ssize_t count = held ? PyTuple_GET_SIZE(held) : 0;
    /* One line alone (a live stream read as it comes) needs no template. */
    Templates *templates = NULL;
    if (no_msgtype != NULL && count > 1 && (templates = PyMem_Calloc(1, sizeof(Templates))) == NULL)
        PyErr_NoMemory();
    PyObject *out = PyErr_Occurred() ? NULL : PyList_New(count);
    LastTopic last = {NULL, NULL, 0};
    for (Py_ssize_t i = 0; out != NULL && i < count; i++) {
        PyObject *line = PyTuple_GET_ITEM(held, i);
        if (!PyBytes_Check(line)) {
            PyErr_Format(PyExc_TypeError, "split_lines takes a list of bytes, not %.80s", Py_TYPE(line)->tp_name);
            Py_CLEAR(out);
            break;
        }
        P s = (P)PyBytes_AS_STRING(line);
        PyObject *message = split_line(s, s + PyBytes_GET_SIZE(line), message_type, no_msgtype, &last, templates);
        if (message == NULL)
            Py_CLEAR(out);
        else
            PyList_SET_ITEM(out, i, message);
    }
    Py_XDECREF(no_msgtype);
    Py_XDECREF(last.text);
    free_templates(templates);
    Py_XDECREF(held);
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
