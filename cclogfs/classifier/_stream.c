/* The default features' live stream in C: features._DefaultStream.push, step for step
 * (issue 14: it was a third of smart logging's time per message).
 *
 * Stream(ints, floats, flags, hypot): ints = (deriv, match, short, long, flip, gap,
 * warmup, gate, despike) in ns (gate, despike: -1 for none), floats = (creep, yaw_flip,
 * dir_flip), flags = (speedup, any_scheme), hypot = math.hypot.
 * push(stamp_ns, row) -> None | (tuple of 11 floats, valid): the same values bit for bit
 * as the Python stream, which stays the reference (tests compare the two on real runs).
 * To keep every double the same: the operations in the Python order, no contraction into
 * fused multiply-adds (setup.py: -ffp-contract=off), cos/sin/atan2 from the same libm
 * as the math module, Python's float % and min/max rules, and math.hypot itself (the C
 * library's hypot differs from it in the last bit for about 1 in 500 pairs here).
 * The deques become ring buffers of (stamp, up to 12 doubles), grown as needed.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#define WIDTH 12

typedef struct {
    long long t;
    double v[WIDTH];
} Entry;

typedef struct {
    Entry *buf;
    Py_ssize_t cap, head, len;
} Ring;

static int ring_push(Ring *r, long long t, const double *v, int n)
{
    if (r->len == r->cap) {
        Py_ssize_t cap = r->cap ? 2 * r->cap : 16;
        Entry *buf = PyMem_Malloc((size_t)cap * sizeof(Entry));
        if (buf == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        for (Py_ssize_t i = 0; i < r->len; i++)
            buf[i] = r->buf[(r->head + i) % r->cap];
        PyMem_Free(r->buf);
        r->buf = buf, r->cap = cap, r->head = 0;
    }
    Entry *e = &r->buf[(r->head + r->len) % r->cap];
    e->t = t;
    memcpy(e->v, v, (size_t)n * sizeof(double));
    r->len++;
    return 0;
}

static Entry *ring_at(Ring *r, Py_ssize_t i) { return &r->buf[(r->head + i) % r->cap]; }
static void ring_pop_front(Ring *r) { r->head = (r->head + 1) % r->cap, r->len--; }
static void ring_clear(Ring *r) { r->head = 0, r->len = 0; }

/* Python's min(a, b) of floats: the first unless the second is smaller. */
static double py_min(double a, double b) { return b < a ? b : a; }

/* Which of a, b, c the Python stream's median max(min(a, b), min(max(a, b), c)) returns
 * (0, 1, 2): the despiked value is that object, an int where the source gave an int. */
static int median_of(double a, double b, double c)
{
    int lo = b < a ? 1 : 0, hi = b > a ? 1 : 0;
    double vlo = lo ? b : a, vhi = hi ? b : a;
    int m2 = c < vhi ? 2 : hi;
    double vm2 = m2 == 2 ? c : vhi;
    return vm2 > vlo ? m2 : lo;
}

/* Python's float %: the sign of the divisor. */
static double py_mod(double v, double w)
{
    double mod = fmod(v, w);
    if (mod) {
        if ((w < 0) != (mod < 0))
            mod += w;
    } else {
        mod = copysign(0.0, w);
    }
    return mod;
}

/* Through pointers, so that the compiler does not fuse cos and sin into sincos. */
static double (*volatile cos_f)(double) = cos;
static double (*volatile sin_f)(double) = sin;

enum { MAXIMA = 7 };

typedef struct {
    PyObject_HEAD
    long long deriv_ns, match_ns, short_ns, long_ns, flip_ns, gap_ns, warmup_ns, gate_ns, despike_ns;
    double creep, yaw_flip, dir_flip;
    int speedup, any_scheme;
    PyObject *hypot, *last;
    int has_prev;
    long long prev_t, seg_start;
    double prev_yaw, prev_vx, prev_vy, prev_wz;
    double cum[5], ext[6];
    int yaw_state, dir_state;
    Ring held1, held2, deriv, match, long_q, yaw_q, dir_q, maxima[MAXIMA];
} Stream;

static Ring *rings(Stream *s, int *n)
{
    *n = 7 + MAXIMA;
    return &s->held1;
}

/* math.hypot(a, b); -1.0 with an exception set on failure (never for finite floats). */
static double hyp(Stream *s, double a, double b)
{
    PyObject *args[2] = {PyFloat_FromDouble(a), PyFloat_FromDouble(b)};
    PyObject *got = NULL;
    if (args[0] != NULL && args[1] != NULL)
        got = PyObject_Vectorcall(s->hypot, args, 2, NULL);
    Py_XDECREF(args[0]);
    Py_XDECREF(args[1]);
    if (got == NULL)
        return -1.0;
    double h = PyFloat_AsDouble(got);
    Py_DECREF(got);
    return h;
}

#define HYP(out, a, b)                                                                                                 \
    do {                                                                                                               \
        out = hyp(self, a, b);                                                                                         \
        if (out == -1.0 && PyErr_Occurred())                                                                           \
            return NULL;                                                                                               \
    } while (0)

static void reset(Stream *s)
{
    int n;
    Ring *r = rings(s, &n);
    for (int i = 0; i < n; i++)
        ring_clear(&r[i]);
    s->has_prev = 0;
    s->seg_start = 0;
    memset(s->cum, 0, sizeof s->cum);
    memset(s->ext, 0, sizeof s->ext);
    s->yaw_state = s->dir_state = 0;
}

/* Count a sign change beyond +-h of x (`_flips` live) and return the flips still in the
 * window, gated as the Python stream gates them. */
static double flips(Stream *s, int *state, Ring *q, double x, double h, long long t, long long window_ns)
{
    if (x > h || x < -h) {
        int sign = x > 0 ? 1 : -1;
        if (*state && sign != *state && ring_push(q, t, NULL, 0) < 0)
            return -1.0;
        *state = sign;
    }
    long long bound = t - window_ns;
    while (q->len && ring_at(q, 0)->t < bound)
        ring_pop_front(q);
    if (s->gate_ns < 0 || (q->len && t - ring_at(q, q->len - 1)->t <= s->gate_ns))
        return (double)q->len;
    return 0.0;
}

static PyObject *Stream_push(Stream *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "push(stamp_ns, row)");
        return NULL;
    }
    long long t = PyLong_AsLongLong(args[0]);
    if (t == -1 && PyErr_Occurred())
        return NULL;
    PyObject *seq = PySequence_Fast(args[1], "row must be a sequence of 13 numbers");
    if (seq == NULL)
        return NULL;
    double row[13];
    int finite = PySequence_Fast_GET_SIZE(seq) == 13;
    /* An int vx (JSON "0", not "0.0") negates to 0, not -0.0: the reverse speed keeps that. */
    double vx_int = finite && PyLong_Check(PySequence_Fast_GET_ITEM(seq, 7));
    for (int i = 0; finite && i < 13; i++) {
        row[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, i));
        if (row[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            return NULL;
        }
        finite = isfinite(row[i]);
    }
    Py_ssize_t got = PySequence_Fast_GET_SIZE(seq);
    Py_DECREF(seq);
    if (got != 13) {
        PyErr_SetString(PyExc_ValueError, "row must hold 13 values");
        return NULL;
    }
    if (!finite || (self->has_prev && t <= self->prev_t))
        return Py_NewRef(self->last);
    if (self->has_prev && t - self->prev_t > self->gap_ns)
        reset(self);

    double x = row[0], y = row[1], qx = row[3], qy = row[4], qz = row[5], qw = row[6];
    double vx = row[7], vy = row[8], wz = row[12];
    double yaw = atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz));
    double *cum = self->cum, *ext = self->ext;
    if (!self->has_prev) {
        self->seg_start = t;
    } else {
        double pyaw = self->prev_yaw, pvx = self->prev_vx, pvy = self->prev_vy, pwz = self->prev_wz;
        double dt = (double)(t - self->prev_t) * 1e-9;
        double dyaw = py_mod(yaw - pyaw + M_PI, 2 * M_PI) - M_PI;
        double mid = pyaw + 0.5 * dyaw;
        double mvx = 0.5 * (vx + pvx), mvy = 0.5 * (vy + pvy), mw = 0.5 * (wz + pwz);
        double c = cos_f(mid), s = sin_f(mid), h;
        cum[0] = cum[0] + (c * mvx - s * mvy) * dt;
        cum[1] = cum[1] + (s * mvx + c * mvy) * dt;
        cum[2] = cum[2] + mw * dt;
        cum[3] = cum[3] + dyaw;
        HYP(h, mvx, mvy);
        if (h < self->creep)
            cum[4] = cum[4] + mw * dt;
        if (self->any_scheme) {
            ext[0] = ext[0] + (c * pvx - s * pvy) * dt;
            ext[1] = ext[1] + (s * pvx + c * pvy) * dt;
            ext[2] = ext[2] + pwz * dt;
            ext[3] = ext[3] + (c * vx - s * vy) * dt;
            ext[4] = ext[4] + (s * vx + c * vy) * dt;
            ext[5] = ext[5] + wz * dt;
        }
    }
    self->has_prev = 1;
    self->prev_t = t, self->prev_yaw = yaw, self->prev_vx = vx, self->prev_vy = vy, self->prev_wz = wz;

    if (self->despike_ns >= 0) { /* the median of now, despike_s ago and twice that ago */
        double now[4] = {vx, vy, wz, vx_int};
        Ring *qs[2] = {&self->held1, &self->held2};
        long long lags[2] = {self->despike_ns, 2 * self->despike_ns};
        for (int k = 0; k < 2; k++) {
            if (ring_push(qs[k], t, now, 4) < 0)
                return NULL;
            while (qs[k]->len > 1 && ring_at(qs[k], 1)->t <= t - lags[k])
                ring_pop_front(qs[k]);
        }
        double *src[3] = {ring_at(&self->held2, 0)->v, ring_at(&self->held1, 0)->v, now}, m[3];
        for (int i = 0; i < 3; i++)
            m[i] = src[median_of(src[0][i], src[1][i], now[i])][i];
        vx_int = src[median_of(src[0][0], src[1][0], now[0])][3];
        vx = m[0], vy = m[1], wz = m[2];
    }

    /* Baselines: the newest entry at least `lag` back, else the segment's first. */
    double dnow[3] = {vx, vy, wz};
    Ring *d = &self->deriv;
    if (ring_push(d, t, dnow, 3) < 0)
        return NULL;
    while (d->len > 1 && ring_at(d, 1)->t <= t - self->deriv_ns)
        ring_pop_front(d);
    Entry *k = ring_at(d, 0);
    long long kt = k->t;
    double kvx = k->v[0], kvy = k->v[1], kwz = k->v[2];
    double span = t > kt ? (double)(t - kt) * 1e-9 : INFINITY;
    double ax = (vx - kvx) / span;

    double mnow[WIDTH] = {x, y, cum[0], cum[1], cum[2], cum[3], ext[0], ext[1], ext[2], ext[3], ext[4], ext[5]};
    Ring *mq = &self->match;
    if (ring_push(mq, t, mnow, WIDTH) < 0)
        return NULL;
    while (mq->len > 1 && ring_at(mq, 1)->t <= t - self->match_ns)
        ring_pop_front(mq);
    Entry *m = ring_at(mq, 0);
    double *mv = m->v, *mext = m->v + 6;
    double mspan = t > m->t ? (double)(t - m->t) * 1e-9 : INFINITY;
    double px = x - mv[0], py = y - mv[1], pose_turn = cum[3] - mv[5];
    double mis, ymis, h;
    HYP(mis, px - (cum[0] - mv[2]), py - (cum[1] - mv[3]));
    ymis = fabs(pose_turn - (cum[2] - mv[4]));
    if (self->any_scheme) {
        for (int j = 0; j <= 3; j += 3) {
            HYP(h, px - (ext[j] - mext[j]), py - (ext[j + 1] - mext[j + 1]));
            mis = py_min(mis, h);
            ymis = py_min(ymis, fabs(pose_turn - (ext[j + 2] - mext[j + 2])));
        }
    }
    double speed, kspeed, inst[MAXIMA];
    HYP(speed, vx, vy);
    if (self->speedup) {
        HYP(kspeed, kvx, kvy);
        inst[0] = (speed - kspeed) / span;
    } else {
        HYP(inst[0], ax, (vy - kvy) / span);
    }
    inst[1] = -ax;
    inst[2] = fabs((wz - kwz) / span);
    inst[3] = speed * fabs(wz);
    inst[4] = vx_int && vx == 0.0 ? 0.0 : -vx;
    inst[5] = mis / mspan;
    inst[6] = ymis / mspan;

    double vec[11];
    vec[0] = fabs(wz);
    long long bound = t - self->short_ns;
    for (int i = 0; i < MAXIMA; i++) { /* running maxima: (t, v), v decreasing */
        Ring *q = &self->maxima[i];
        while (q->len && ring_at(q, q->len - 1)->v[0] <= inst[i])
            q->len--;
        if (ring_push(q, t, &inst[i], 1) < 0)
            return NULL;
        while (ring_at(q, 0)->t < bound)
            ring_pop_front(q);
        vec[1 + i] = ring_at(q, 0)->v[0];
    }
    if (vec[5] < 0.0)
        vec[5] = 0.0; /* reverse speed: none is 0, not -speed */
    if (vec[1] < 0.0 && self->speedup)
        vec[1] = 0.0; /* only slowing down: 0 */

    Ring *lq = &self->long_q;
    if (ring_push(lq, t, &cum[4], 1) < 0)
        return NULL;
    while (ring_at(lq, 0)->t < t - self->long_ns)
        ring_pop_front(lq);
    if (self->gate_ns < 0 || (speed < self->creep && fabs(wz) > self->yaw_flip))
        vec[8] = fabs(cum[4] - ring_at(lq, 0)->v[0]);
    else
        vec[8] = 0.0;
    vec[9] = flips(self, &self->yaw_state, &self->yaw_q, wz, self->yaw_flip, t, self->flip_ns);
    vec[10] = flips(self, &self->dir_state, &self->dir_q, vx, self->dir_flip, t, self->long_ns);
    if ((vec[9] == -1.0 || vec[10] == -1.0) && PyErr_Occurred())
        return NULL;

    PyObject *values = PyTuple_New(11);
    if (values == NULL)
        return NULL;
    for (int i = 0; i < 11; i++) {
        PyObject *f = PyFloat_FromDouble(vec[i]);
        if (f == NULL) {
            Py_DECREF(values);
            return NULL;
        }
        PyTuple_SET_ITEM(values, i, f);
    }
    PyObject *last = Py_BuildValue("(NO)", values, t - self->seg_start >= self->warmup_ns ? Py_True : Py_False);
    if (last == NULL)
        return NULL;
    Py_SETREF(self->last, last);
    return Py_NewRef(last);
}

static int Stream_init(Stream *self, PyObject *args, PyObject *kwds)
{
    PyObject *hypot;
    if (!PyArg_ParseTuple(args, "(LLLLLLLLL)(ddd)(pp)O", &self->deriv_ns, &self->match_ns, &self->short_ns,
                          &self->long_ns, &self->flip_ns, &self->gap_ns, &self->warmup_ns, &self->gate_ns,
                          &self->despike_ns, &self->creep, &self->yaw_flip, &self->dir_flip, &self->speedup,
                          &self->any_scheme, &hypot))
        return -1;
    Py_XSETREF(self->hypot, Py_NewRef(hypot));
    Py_XSETREF(self->last, Py_NewRef(Py_None));
    reset(self);
    return 0;
}

static void Stream_dealloc(Stream *self)
{
    int n;
    Ring *r = rings(self, &n);
    for (int i = 0; i < n; i++)
        PyMem_Free(r[i].buf);
    Py_XDECREF(self->hypot);
    Py_XDECREF(self->last);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyMethodDef Stream_methods[] = {
    {"push", (PyCFunction)(void (*)(void))Stream_push, METH_FASTCALL,
     "push(stamp_ns, row) -> None or (11 floats, valid), as _DefaultStream.push."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject StreamType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "cclogfs.classifier._stream.Stream",
    .tp_basicsize = sizeof(Stream),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Stream_init,
    .tp_dealloc = (destructor)Stream_dealloc,
    .tp_methods = Stream_methods,
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_stream", NULL, -1, NULL};

PyMODINIT_FUNC PyInit__stream(void)
{
    if (PyType_Ready(&StreamType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m != NULL && PyModule_AddObjectRef(m, "Stream", (PyObject *)&StreamType) < 0)
        Py_CLEAR(m);
    return m;
}
