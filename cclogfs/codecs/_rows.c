/* The value tokens of a window's texts in one shape: shapes._rows_python in C (issue 14).
 *
 * match_rows(literals, kinds, texts) -> [tuple of value tokens, or None] per text, exactly
 * what shapes._matcher's regex gives (fullmatch(text).groups(), None where it does not
 * match): literals[0] value[0] literals[1] ... value[k-1] literals[k], where a value is
 *   kinds[i] true:  a JSON string token  "[^"\\]*(?:\\.[^"\\]*)*"
 *   kinds[i] false: a number-like token  [-+.0-9A-Za-z]++  (possessive: the longest run)
 * Both tokens are found by one forward scan: a string ends at its first unescaped quote
 * (the regex cannot end it elsewhere), a number takes every character of its class.
 *
 * match_columns(literals, kinds, texts) -> the same tokens by slot, one entry per slot, or
 * None if any text does not match. A string slot's entry is a list of one token per text
 * (the rows transposed); a number slot's is one str, its tokens joined by "," (a number
 * token holds no comma, so split(",") gives them back), or its one token when all of them
 * are the same (a constant column). The encoder works a column at a
 * time, and it parses and compares a number column as that joined text: one object per
 * column instead of one per text (a window of 200 odometry messages has ~2,000 number
 * tokens, whose objects cost more than finding them; issue 14, eighth pass).
 *
 * join_rows(literals, columns) is the way back, for the decoder: each row's text, the
 * literals and that row's values alternating (see below).
 *
 * Only texts and literals of one byte per character (ASCII and Latin-1, as robot JSON
 * is) are handled; for any other both functions return NotImplemented and the caller
 * takes the regex path. Optional: cclogfs works without it (shapes.py says how).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

/* The characters of a number token ([-+.0-9A-Za-z]), filled by init_number_chars: one
 * lookup a character instead of up to six comparisons, in the loop that reads most of
 * the characters a window's literals do not cover (issue 14, ninth pass). */
static unsigned char number_char[256];

static void init_number_chars(void)
{
    for (unsigned c = 0; c < 256; c++)
        number_char[c] = c == '-' || c == '+' || c == '.' || (c >= '0' && c <= '9') || (c >= 'A' && c <= 'Z') ||
                         (c >= 'a' && c <= 'z');
}

/* The end of the value token starting at s[i], or -1 if none starts there. */
static Py_ssize_t token_end(const unsigned char *s, Py_ssize_t i, Py_ssize_t n, int is_string)
{
    if (is_string) {
        if (i >= n || s[i] != '"')
            return -1;
        for (i++; i < n; i++) {
            if (s[i] == '"')
                return i + 1;
            if (s[i] == '\\' && ++i >= n)
                return -1;
        }
        return -1;
    }
    Py_ssize_t start = i;
    while (i < n && number_char[s[i]])
        i++;
    return i > start ? i : -1;
}

/* A shape's literals and value kinds in C arrays, and room for one text's value spans. */
struct shape {
    Py_ssize_t k;  /* value slots */
    const unsigned char **lit;
    Py_ssize_t *lit_len;
    int *kinds;
    Py_ssize_t *starts, *ends;
};

/* Whether the text matches the shape; if so, its values' spans are in sh->starts, sh->ends. */
static int find_values(PyObject *text, const struct shape *sh)
{
    const unsigned char *s = PyUnicode_1BYTE_DATA(text);
    Py_ssize_t n = PyUnicode_GET_LENGTH(text), pos = 0;
    for (Py_ssize_t j = 0; j <= sh->k; j++) {
        if (n - pos < sh->lit_len[j] || memcmp(s + pos, sh->lit[j], sh->lit_len[j]) != 0)
            return 0;
        pos += sh->lit_len[j];
        if (j == sh->k)
            break;
        Py_ssize_t end = token_end(s, pos, n, sh->kinds[j]);
        if (end < 0)
            return 0;
        sh->starts[j] = pos;
        sh->ends[j] = pos = end;
    }
    return pos == n;
}

static int one_byte(PyObject *s)
{
    return PyUnicode_Check(s) && PyUnicode_READY(s) == 0 && PyUnicode_KIND(s) == PyUnicode_1BYTE_KIND;
}

static void shape_free(struct shape *sh)
{
    PyMem_Free(sh->lit);
    PyMem_Free(sh->lit_len);
    PyMem_Free(sh->kinds);
    PyMem_Free(sh->starts);
}

/* Parse (literals, kinds, texts) into sh and *texts, a new tuple of the texts (the
 * caller releases it): 1 done, 0 a string of wider characters (the caller returns
 * NotImplemented), -1 an error (set). The texts are read from that tuple, not from the
 * list: making an object may run the garbage collector, and a finalizer, or a kind's
 * __bool__, could change the list while it is read. */
static int shape_init(PyObject *args, const char *name, struct shape *sh, PyObject **texts)
{
    PyObject *literals, *kinds_obj, *list;
    char format[64];
    memset(sh, 0, sizeof *sh);
    *texts = NULL;
    PyOS_snprintf(format, sizeof format, "O!O!O!:%s", name);
    if (!PyArg_ParseTuple(args, format, &PyTuple_Type, &literals, &PyTuple_Type, &kinds_obj, &PyList_Type, &list))
        return -1;
    Py_ssize_t k = sh->k = PyTuple_GET_SIZE(kinds_obj);
    if (PyTuple_GET_SIZE(literals) != k + 1) {
        PyErr_Format(PyExc_ValueError, "%s needs one literal more than kinds", name);
        return -1;
    }
    for (Py_ssize_t j = 0; j <= k; j++)
        if (!one_byte(PyTuple_GET_ITEM(literals, j)))
            return 0;
    /* Not PyList_AsTuple: on 3.11 it reads the list's items, then makes the tuple (which
     * may run the collector, and a finalizer), then copies from what it read. Here the
     * tuple is made first, and the list's size checked after it. */
    Py_ssize_t count = PyList_GET_SIZE(list);
    if ((*texts = PyTuple_New(count)) == NULL)
        return -1;
    if (PyList_GET_SIZE(list) != count) {
        Py_CLEAR(*texts);
        PyErr_Format(PyExc_RuntimeError, "%s: the texts changed while being read", name);
        return -1;
    }
    for (Py_ssize_t i = 0; i < count; i++)
        PyTuple_SET_ITEM(*texts, i, Py_NewRef(PyList_GET_ITEM(list, i)));
    for (Py_ssize_t i = 0; i < count; i++)
        if (!one_byte(PyTuple_GET_ITEM(*texts, i))) {
            Py_CLEAR(*texts);
            return 0;
        }
    sh->lit = PyMem_Malloc((k + 1) * sizeof *sh->lit);
    sh->lit_len = PyMem_Malloc((k + 1) * sizeof *sh->lit_len);
    sh->kinds = PyMem_Malloc((k + 1) * sizeof *sh->kinds);
    sh->starts = PyMem_Malloc(2 * (k + 1) * sizeof *sh->starts);  /* each value's start, then end */
    if (sh->lit == NULL || sh->lit_len == NULL || sh->kinds == NULL || sh->starts == NULL) {
        shape_free(sh);
        Py_CLEAR(*texts);
        PyErr_NoMemory();
        return -1;
    }
    sh->ends = sh->starts + k + 1;
    for (Py_ssize_t j = 0; j <= k; j++) {
        PyObject *l = PyTuple_GET_ITEM(literals, j);
        sh->lit[j] = PyUnicode_1BYTE_DATA(l);
        sh->lit_len[j] = PyUnicode_GET_LENGTH(l);
        if (j < k && (sh->kinds[j] = PyObject_IsTrue(PyTuple_GET_ITEM(kinds_obj, j))) < 0) {
            shape_free(sh);
            Py_CLEAR(*texts);
            return -1;
        }
    }
    return 1;
}

/* The row of a text that find_values matched: a new tuple of its value tokens. */
static PyObject *row_of(PyObject *text, const struct shape *sh)
{
    PyObject *row = PyTuple_New(sh->k);
    if (row == NULL)
        return NULL;
    for (Py_ssize_t j = 0; j < sh->k; j++) {
        PyObject *token = PyUnicode_Substring(text, sh->starts[j], sh->ends[j]);
        if (token == NULL) {
            Py_DECREF(row);
            return NULL;
        }
        PyTuple_SET_ITEM(row, j, token);
    }
    return row;
}

static PyObject *match_rows(PyObject *Py_UNUSED(self), PyObject *args)
{
    struct shape sh;
    PyObject *texts;
    int ready = shape_init(args, "match_rows", &sh, &texts);
    if (ready <= 0)
        return ready < 0 ? NULL : Py_NewRef(Py_NotImplemented);
    Py_ssize_t count = PyTuple_GET_SIZE(texts);
    PyObject *out = PyList_New(count);
    for (Py_ssize_t i = 0; out != NULL && i < count; i++) {
        PyObject *text = PyTuple_GET_ITEM(texts, i);
        PyObject *row = find_values(text, &sh) ? row_of(text, &sh) : Py_NewRef(Py_None);
        if (row == NULL)
            Py_CLEAR(out);
        else
            PyList_SET_ITEM(out, i, row);
    }
    shape_free(&sh);
    Py_DECREF(texts);
    return out;
}

/* A number slot's tokens, found at spans[i * k + j] (start, end) for each text i, joined by
 * ",": a new ASCII str (number tokens are [-+.0-9A-Za-z] only). */
static PyObject *joined_tokens(PyObject *texts, const Py_ssize_t *spans, Py_ssize_t k, Py_ssize_t j)
{
    Py_ssize_t count = PyTuple_GET_SIZE(texts), size = count > 0 ? count - 1 : 0;
    for (Py_ssize_t i = 0; i < count; i++)
        size += spans[2 * (i * k + j) + 1] - spans[2 * (i * k + j)];
    PyObject *out = PyUnicode_New(size, 127);
    if (out == NULL)
        return NULL;
    Py_UCS1 *at = PyUnicode_1BYTE_DATA(out);
    for (Py_ssize_t i = 0; i < count; i++) {
        Py_ssize_t start = spans[2 * (i * k + j)], len = spans[2 * (i * k + j) + 1] - start;
        if (i > 0)
            *at++ = ',';
        memcpy(at, PyUnicode_1BYTE_DATA(PyTuple_GET_ITEM(texts, i)) + start, len);
        at += len;
    }
    return out;
}

/* Whether a number slot's tokens at spans[i * k + j] are all the same, then given as that
 * one token rather than n copies joined: a slot whose value held still for the window.
 * A shape reused from the window before keeps that window's varying slots, so long runs
 * carry many (11 of 23 number slots in most windows of `bench speed`'s simulated
 * odometry); joining them, and joining the first token n times to find them constant,
 * was most of what such a run costs more per message (issue 14, ninth pass). */
static int same_tokens(PyObject *texts, const Py_ssize_t *spans, Py_ssize_t k, Py_ssize_t j)
{
    Py_ssize_t count = PyTuple_GET_SIZE(texts), start = spans[2 * j], len = spans[2 * j + 1] - start;
    const Py_UCS1 *first = PyUnicode_1BYTE_DATA(PyTuple_GET_ITEM(texts, 0)) + start;
    for (Py_ssize_t i = 1; i < count; i++) {
        Py_ssize_t at = spans[2 * (i * k + j)];
        if (spans[2 * (i * k + j) + 1] - at != len ||
            memcmp(PyUnicode_1BYTE_DATA(PyTuple_GET_ITEM(texts, i)) + at, first, len) != 0)
            return 0;
    }
    return 1;
}

static PyObject *match_columns(PyObject *Py_UNUSED(self), PyObject *args)
{
    struct shape sh;
    PyObject *texts;
    int ready = shape_init(args, "match_columns", &sh, &texts);
    if (ready <= 0)
        return ready < 0 ? NULL : Py_NewRef(Py_NotImplemented);
    Py_ssize_t count = PyTuple_GET_SIZE(texts), k = sh.k;
    /* Every text's value spans first: a joined column's size is known only after the last. */
    Py_ssize_t *spans = PyMem_Malloc(2 * (count * k + 1) * sizeof *spans);
    PyObject *out = spans == NULL ? PyErr_NoMemory() : PyList_New(k);
    for (Py_ssize_t i = 0; out != NULL && i < count; i++) {
        if (!find_values(PyTuple_GET_ITEM(texts, i), &sh)) {
            Py_SETREF(out, Py_NewRef(Py_None));
            break;
        }
        for (Py_ssize_t j = 0; j < k; j++) {
            spans[2 * (i * k + j)] = sh.starts[j];
            spans[2 * (i * k + j) + 1] = sh.ends[j];
        }
    }
    for (Py_ssize_t j = 0; out != NULL && out != Py_None && j < k; j++) {
        PyObject *column;
        if (sh.kinds[j]) {
            column = PyList_New(count);
            for (Py_ssize_t i = 0; column != NULL && i < count; i++) {
                Py_ssize_t at = 2 * (i * k + j);
                PyObject *token = PyUnicode_Substring(PyTuple_GET_ITEM(texts, i), spans[at], spans[at + 1]);
                if (token == NULL)
                    Py_CLEAR(column);
                else
                    PyList_SET_ITEM(column, i, token);
            }
        } else if (count > 0 && same_tokens(texts, spans, k, j)) {
            column = PyUnicode_Substring(PyTuple_GET_ITEM(texts, 0), spans[2 * j], spans[2 * j + 1]);
        } else {
            column = joined_tokens(texts, spans, k, j);
        }
        if (column == NULL)
            Py_CLEAR(out);
        else
            PyList_SET_ITEM(out, j, column);
    }
    PyMem_Free(spans);
    shape_free(&sh);
    Py_DECREF(texts);
    return out;
}

/* join_rows(literals, columns) -> [literals[0] + columns[0][i] + literals[1] + ... +
 * columns[-1][i] + literals[-1] for each row i]: the texts of a decoded group, its
 * constant columns already folded into the literals. What `fmt % row` gives, in one pass
 * of copies: % reads its template a character at a time, and an odometry template is
 * ~800 characters around 9 values, so filling it in was a quarter of decoding a window
 * (issue 14, twelfth pass). Strings of one byte per character only (ASCII and Latin-1);
 * for any other, NotImplemented and the caller formats with %. */
static PyObject *join_rows(PyObject *Py_UNUSED(self), PyObject *args)
{
    PyObject *literals, *columns;
    if (!PyArg_ParseTuple(args, "O!O!:join_rows", &PyTuple_Type, &literals, &PyTuple_Type, &columns))
        return NULL;
    Py_ssize_t k = PyTuple_GET_SIZE(columns), n = 0, fixed = 0;
    if (k == 0 || PyTuple_GET_SIZE(literals) != k + 1) {
        PyErr_SetString(PyExc_ValueError, "join_rows needs one column or more and one literal more than columns");
        return NULL;
    }
    int fixed_ascii = 1;
    Py_ssize_t fixed_pieces = 0;  /* the literals that are not empty, and the last of them */
    PyObject *fixed_piece = PyTuple_GET_ITEM(literals, 0);
    for (Py_ssize_t j = 0; j <= k; j++) {
        PyObject *l = PyTuple_GET_ITEM(literals, j);
        if (!one_byte(l))
            return Py_NewRef(Py_NotImplemented);
        fixed += PyUnicode_GET_LENGTH(l);
        fixed_ascii &= PyUnicode_IS_ASCII(l);
        if (PyUnicode_GET_LENGTH(l) > 0) {
            fixed_pieces++;
            fixed_piece = l;
        }
    }
    if (PyList_Check(PyTuple_GET_ITEM(columns, 0)))
        n = PyList_GET_SIZE(PyTuple_GET_ITEM(columns, 0));
    /* The list first: making it may run the garbage collector, and a finalizer could change
     * the columns; after the checks below, nothing runs Python code (a str is not tracked). */
    PyObject *out = PyList_New(n);
    if (out == NULL)
        return NULL;
    for (Py_ssize_t j = 0; j < k; j++) {
        PyObject *column = PyTuple_GET_ITEM(columns, j);
        if (!PyList_Check(column) || PyList_GET_SIZE(column) != n) {
            Py_DECREF(out);
            PyErr_SetString(PyExc_ValueError, "join_rows needs lists of one length");
            return NULL;
        }
        for (Py_ssize_t i = 0; i < n; i++)
            if (!one_byte(PyList_GET_ITEM(column, i))) {
                Py_DECREF(out);
                return Py_NewRef(Py_NotImplemented);
            }
    }
    for (Py_ssize_t i = 0; out != NULL && i < n; i++) {
        Py_ssize_t size = fixed, pieces = fixed_pieces;
        PyObject *piece = fixed_piece;
        int ascii = fixed_ascii;
        for (Py_ssize_t j = 0; j < k; j++) {
            PyObject *value = PyList_GET_ITEM(PyTuple_GET_ITEM(columns, j), i);
            size += PyUnicode_GET_LENGTH(value);
            ascii &= PyUnicode_IS_ASCII(value);
            if (PyUnicode_GET_LENGTH(value) > 0) {
                pieces++;
                piece = value;
            }
        }
        /* A text that is one piece (a bare value, "" when all are empty) is that piece, as %
         * gives it: a window of a million bare numbers would otherwise hold each twice, a
         * third more memory, past what FORMAT.md lets a read take (test_codec_bombs.py). */
        if (pieces <= 1) {
            PyList_SET_ITEM(out, i, Py_NewRef(piece));
            continue;
        }
        /* An ASCII str must be made as one (127): str.isascii and the UTF-8 encoder trust the flag. */
        PyObject *text = PyUnicode_New(size, ascii ? 127 : 255);
        if (text == NULL) {
            Py_CLEAR(out);
            break;
        }
        Py_UCS1 *at = PyUnicode_1BYTE_DATA(text);
        for (Py_ssize_t j = 0; j <= k; j++) {
            PyObject *l = PyTuple_GET_ITEM(literals, j);
            memcpy(at, PyUnicode_1BYTE_DATA(l), PyUnicode_GET_LENGTH(l));
            at += PyUnicode_GET_LENGTH(l);
            if (j == k)
                break;
            PyObject *value = PyList_GET_ITEM(PyTuple_GET_ITEM(columns, j), i);
            memcpy(at, PyUnicode_1BYTE_DATA(value), PyUnicode_GET_LENGTH(value));
            at += PyUnicode_GET_LENGTH(value);
        }
        PyList_SET_ITEM(out, i, text);
    }
    return out;
}

static PyMethodDef methods[] = {
    {"match_rows", match_rows, METH_VARARGS,
     "match_rows(literals, kinds, texts): each text's value tokens in the shape, or None."},
    {"match_columns", match_columns, METH_VARARGS,
     "match_columns(literals, kinds, texts): each slot's value tokens (a number slot's joined by ','); None if a text misses."},
    {"join_rows", join_rows, METH_VARARGS,
     "join_rows(literals, columns): each row's text, literals and the row's values alternating."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_rows", NULL, -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__rows(void)
{
    init_number_chars();
    return PyModule_Create(&module);
}
