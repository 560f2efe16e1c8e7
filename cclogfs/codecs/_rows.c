/* The value rows of a window's texts in one shape: shapes._rows_python in C (issue 14).
 *
 * match_rows(literals, kinds, texts) -> [tuple of value tokens, or None] per text, exactly
 * what shapes._matcher's regex gives (fullmatch(text).groups(), None where it does not
 * match): literals[0] value[0] literals[1] ... value[k-1] literals[k], where a value is
 *   kinds[i] true:  a JSON string token  "[^"\\]*(?:\\.[^"\\]*)*"
 *   kinds[i] false: a number-like token  [-+.0-9A-Za-z]++  (possessive: the longest run)
 * Both tokens are found by one forward scan: a string ends at its first unescaped quote
 * (the regex cannot end it elsewhere), a number takes every character of its class.
 *
 * Only texts and literals of one byte per character (ASCII and Latin-1, as robot JSON
 * is) are handled; for any other the function returns NotImplemented and the caller
 * takes the regex path. Optional: cclogfs works without it (shapes.py says how).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

static int is_number_char(unsigned char c)
{
    return c == '-' || c == '+' || c == '.' || (c >= '0' && c <= '9') || (c >= 'A' && c <= 'Z') ||
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
    while (i < n && is_number_char(s[i]))
        i++;
    return i > start ? i : -1;
}

/* One text's row (a new tuple), Py_None (new reference) when it does not match, NULL on error. */
static PyObject *match_one(PyObject *text, Py_ssize_t k, const unsigned char **lit, const Py_ssize_t *lit_len,
                           const int *kinds, Py_ssize_t *starts, Py_ssize_t *ends)
{
    const unsigned char *s = PyUnicode_1BYTE_DATA(text);
    Py_ssize_t n = PyUnicode_GET_LENGTH(text), pos = 0;
    for (Py_ssize_t j = 0; j <= k; j++) {
        if (n - pos < lit_len[j] || memcmp(s + pos, lit[j], lit_len[j]) != 0)
            Py_RETURN_NONE;
        pos += lit_len[j];
        if (j == k)
            break;
        Py_ssize_t end = token_end(s, pos, n, kinds[j]);
        if (end < 0)
            Py_RETURN_NONE;
        starts[j] = pos;
        ends[j] = pos = end;
    }
    if (pos != n)
        Py_RETURN_NONE;
    PyObject *row = PyTuple_New(k);
    if (row == NULL)
        return NULL;
    for (Py_ssize_t j = 0; j < k; j++) {
        PyObject *token = PyUnicode_Substring(text, starts[j], ends[j]);
        if (token == NULL) {
            Py_DECREF(row);
            return NULL;
        }
        PyTuple_SET_ITEM(row, j, token);
    }
    return row;
}

static int one_byte(PyObject *s)
{
    return PyUnicode_Check(s) && PyUnicode_READY(s) == 0 && PyUnicode_KIND(s) == PyUnicode_1BYTE_KIND;
}

static PyObject *match_rows(PyObject *Py_UNUSED(self), PyObject *args)
{
    PyObject *literals, *kinds_obj, *texts;
    if (!PyArg_ParseTuple(args, "O!O!O!:match_rows", &PyTuple_Type, &literals, &PyTuple_Type, &kinds_obj,
                          &PyList_Type, &texts))
        return NULL;
    Py_ssize_t k = PyTuple_GET_SIZE(kinds_obj), count = PyList_GET_SIZE(texts);
    if (PyTuple_GET_SIZE(literals) != k + 1) {
        PyErr_SetString(PyExc_ValueError, "match_rows needs one literal more than kinds");
        return NULL;
    }
    for (Py_ssize_t j = 0; j <= k; j++)
        if (!one_byte(PyTuple_GET_ITEM(literals, j)))
            Py_RETURN_NOTIMPLEMENTED;
    for (Py_ssize_t i = 0; i < count; i++)
        if (!one_byte(PyList_GET_ITEM(texts, i)))
            Py_RETURN_NOTIMPLEMENTED;
    const unsigned char **lit = PyMem_Malloc((k + 1) * sizeof *lit);
    Py_ssize_t *lit_len = PyMem_Malloc((k + 1) * sizeof *lit_len);
    int *kinds = PyMem_Malloc((k + 1) * sizeof *kinds);
    Py_ssize_t *spans = PyMem_Malloc(2 * (k + 1) * sizeof *spans);  /* each value's start, then end */
    PyObject *out = NULL;
    if (lit == NULL || lit_len == NULL || kinds == NULL || spans == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t j = 0; j <= k; j++) {
        PyObject *l = PyTuple_GET_ITEM(literals, j);
        lit[j] = PyUnicode_1BYTE_DATA(l);
        lit_len[j] = PyUnicode_GET_LENGTH(l);
        if (j < k && (kinds[j] = PyObject_IsTrue(PyTuple_GET_ITEM(kinds_obj, j))) < 0)
            goto done;
    }
    out = PyList_New(count);
    if (out == NULL)
        goto done;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *row = match_one(PyList_GET_ITEM(texts, i), k, lit, lit_len, kinds, spans, spans + k + 1);
        if (row == NULL) {
            Py_CLEAR(out);
            goto done;
        }
        PyList_SET_ITEM(out, i, row);
    }
done:
    PyMem_Free(lit);
    PyMem_Free(lit_len);
    PyMem_Free(kinds);
    PyMem_Free(spans);
    return out;
}

static PyMethodDef methods[] = {
    {"match_rows", match_rows, METH_VARARGS,
     "match_rows(literals, kinds, texts): each text's value tokens in the shape, or None."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_rows", NULL, -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__rows(void)
{
    return PyModule_Create(&module);
}
