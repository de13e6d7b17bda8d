/* The planned single-state step of fusion.core.compiled_packed, as a CPython extension.
 *
 * step(x, P, z, blob, t_ns) -> Update | int
 *
 * The same arithmetic as compiled_packed.step_packed on the same packed blob (layout in that
 * module's docstring): every product and sum in the same order, no fused multiply-add (built
 * with -ffp-contract=off), the same libm calls, so the same bits (tests/core/test_packed_c.py).
 * What it adds is what a numba call cannot: it takes its five arguments without typing each one
 * through a dispatcher, allocates the four results itself, and returns the Update (a
 * GaussianState x+, P+ at t_ns, y, S, NIS, log-likelihood) built in place. On a status other
 * than OK it returns the status (an int, compiled_step's codes), and NOT_TAKEN (-1) where an
 * argument is not an aligned native float64 array of the number of dimensions the step needs
 * (the caller then takes the numba kernel, which reads any layout).
 *
 * bind(GaussianState, Update) must be called once before step (fusion.core.packed_step does).
 * Holds the GIL throughout; the blob's scratch is only ever used inside one call.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <math.h>

enum { OK = 0, NONFINITE = 1, SHAPE = 2, BAD_Z = 3, BAD_R = 4, S_NOT_PD = 5, NOT_TAKEN = -1 };
enum { CHECK_Z = 1, HEAD = 4, KERNEL_CARTESIAN = 1, KERNEL_RADAR2D = 2 };

static const double PI = 3.141592653589793;
static const double TWO_PI = 6.283185307179586;

static PyTypeObject *state_type = NULL;  /* fusion.core.gaussian.GaussianState */
static PyTypeObject *update_type = NULL; /* fusion.core.gaussian.Update */

/* A float of the blob as an index, as numba's int(): truncated; -1 where it is no index at all. */
static Py_ssize_t as_index(double v) {
    if (!(v > -1e9 && v < 1e9)) return -1;
    return (Py_ssize_t)v;
}

/* compiled_step.wrap: pi - ((pi - a) mod 2 pi) into (-pi, pi]. */
static double wrap(double a) {
    double r = PI - fmod(PI - a, TWO_PI);
    if (r > PI) r -= TWO_PI;
    if (fabs(r) > PI - 1e-9) {
        double md = fmod(PI - a, TWO_PI);
        if (md < 0.0) md += TWO_PI;
        double w = PI - md;
        return w <= -PI ? w + TWO_PI : w;
    }
    return r;
}

/* compiled_packed._model: h(x-) into b[zh:], H (zeroed first) into b[H:]; 0 where the spec
 * does not fit. */
static int model(int kind, Py_ssize_t sp, double *b, Py_ssize_t n, Py_ssize_t m, Py_ssize_t xp,
                 Py_ssize_t H, Py_ssize_t zh) {
    for (Py_ssize_t i = 0; i < m * n; i++) b[H + i] = 0.0;
    if (kind == KERNEL_CARTESIAN) {
        if (as_index(b[3]) != 2 + 2 * m + m * m || as_index(b[sp]) != n) return 0;
        for (Py_ssize_t i = 0; i < m; i++) {
            Py_ssize_t c = as_index(b[sp + 2 + i]);
            if (!(0 <= c && c < n)) return 0;
        }
        int posed = b[sp + 1] != 0.0;
        Py_ssize_t rot = sp + 2 + 2 * m;
        for (Py_ssize_t j = 0; j < m; j++) {
            if (posed) {
                double s = 0.0;
                for (Py_ssize_t i = 0; i < m; i++) {
                    Py_ssize_t c = as_index(b[sp + 2 + i]);
                    s += (b[xp + c] - b[sp + 2 + m + i]) * b[rot + i * m + j];
                    b[H + j * n + c] += b[rot + i * m + j];
                }
                b[zh + j] = s;
            } else {
                Py_ssize_t c = as_index(b[sp + 2 + j]);
                b[zh + j] = b[xp + c];
                b[H + j * n + c] = 1.0;
            }
        }
        return 1;
    }
    if (kind != KERNEL_RADAR2D) return 0;
    int rr = b[sp + 7] != 0.0;
    if (as_index(b[3]) != 8 || m != (rr ? 3 : 2)) return 0;
    Py_ssize_t ix = as_index(b[sp + 3]), iy = as_index(b[sp + 4]);
    Py_ssize_t jvx = as_index(b[sp + 5]), jvy = as_index(b[sp + 6]);
    if (!(0 <= ix && ix < n && 0 <= iy && iy < n && 0 <= jvx && jvx < n && 0 <= jvy && jvy < n)) return 0;
    double dx = b[xp + ix] - b[sp];
    double dy = b[xp + iy] - b[sp + 1];
    double r = hypot(dx, dy);
    b[zh] = r;
    b[zh + 1] = wrap(atan2(dy, dx) - b[sp + 2]);
    double r2 = dx * dx + dy * dy;
    double rj = sqrt(r2);
    b[H + ix] = dx / rj;
    b[H + iy] = dy / rj;
    b[H + n + ix] = -dy / r2;
    b[H + n + iy] = dx / r2;
    if (rr) {
        double vx = b[xp + jvx], vy = b[xp + jvy];
        b[zh + 2] = (dx * vx + dy * vy) / r;
        double cross = vx * dy - vy * dx;
        b[H + 2 * n + ix] = dy * cross / (r2 * rj);
        b[H + 2 * n + iy] = -dx * cross / (r2 * rj);
        b[H + 2 * n + jvx] = dx / rj;
        b[H + 2 * n + jvy] = dy / rj;
    }
    return 1;
}

/* compiled_packed._update (compiled.update_work on flat offsets): the Joseph-form update into
 * xn, Pn, S (C-contiguous), NIS and log-likelihood; 0 where S is not positive definite. */
static int update(double *b, Py_ssize_t n, Py_ssize_t m, Py_ssize_t xp, Py_ssize_t Pp, Py_ssize_t H,
                  Py_ssize_t R, Py_ssize_t w0, const double *y, double *xn, double *Pn, double *S,
                  double *nis_out, double *ll_out) {
    Py_ssize_t mn = m * n;
    Py_ssize_t W = w0 + mn, Kt = w0 + 2 * mn, KS = w0 + 3 * mn, L = w0 + 4 * mn;
    Py_ssize_t w = L + m * m;
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < n; j++) {
            double s = 0.0;
            for (Py_ssize_t k = 0; k < n; k++) s += b[H + i * n + k] * b[Pp + k * n + j];
            b[w0 + i * n + j] = s;
        }
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < m; j++) {
            double s = 0.0;
            for (Py_ssize_t k = 0; k < n; k++) s += b[w0 + i * n + k] * b[H + j * n + k];
            S[i * m + j] = s + b[R + i * m + j];
        }
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < i; j++) {
            double a = 0.5 * (S[i * m + j] + S[j * m + i]);
            S[i * m + j] = a;
            S[j * m + i] = a;
        }
    for (Py_ssize_t j = 0; j < m; j++) {
        double d = S[j * m + j];
        for (Py_ssize_t k = 0; k < j; k++) d -= b[L + j * m + k] * b[L + j * m + k];
        if (!(d > 0.0)) return 0;
        b[L + j * m + j] = sqrt(d);
        for (Py_ssize_t i = j + 1; i < m; i++) {
            double s = S[i * m + j];
            for (Py_ssize_t k = 0; k < j; k++) s -= b[L + i * m + k] * b[L + j * m + k];
            b[L + i * m + j] = s / b[L + j * m + j];
        }
    }
    for (Py_ssize_t i = 0; i < m; i++) {
        double lii = b[L + i * m + i];
        for (Py_ssize_t j = 0; j < n; j++) {
            double s = b[w0 + i * n + j];
            for (Py_ssize_t k = 0; k < i; k++) s -= b[L + i * m + k] * b[W + k * n + j];
            b[W + i * n + j] = s / lii;
        }
        double s = y[i];
        for (Py_ssize_t k = 0; k < i; k++) s -= b[L + i * m + k] * b[w + k];
        b[w + i] = s / lii;
    }
    for (Py_ssize_t i = m - 1; i >= 0; i--) {
        double lii = b[L + i * m + i];
        for (Py_ssize_t j = 0; j < n; j++) {
            double s = b[W + i * n + j];
            for (Py_ssize_t k = i + 1; k < m; k++) s -= b[L + k * m + i] * b[Kt + k * n + j];
            b[Kt + i * n + j] = s / lii;
        }
    }
    double nis = 0.0, logdet = 0.0;
    for (Py_ssize_t i = 0; i < m; i++) {
        nis += b[w + i] * b[w + i];
        logdet += 2.0 * log(b[L + i * m + i]);
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        double s = b[xp + i];
        for (Py_ssize_t k = 0; k < m; k++) s += b[Kt + k * n + i] * y[k];
        xn[i] = s;
    }
    for (Py_ssize_t i = 0; i < n; i++)
        for (Py_ssize_t j = 0; j < m; j++) {
            double s = 0.0;
            for (Py_ssize_t k = 0; k < m; k++) s += b[Kt + k * n + i] * S[k * m + j];
            b[KS + i * m + j] = s;
        }
    for (Py_ssize_t i = 0; i < n; i++)
        for (Py_ssize_t j = 0; j < n; j++) {
            double a_ij = 0.0, a_ji = 0.0, ksk = 0.0;
            for (Py_ssize_t k = 0; k < m; k++) {
                a_ij += b[Kt + k * n + i] * b[w0 + k * n + j];
                a_ji += b[Kt + k * n + j] * b[w0 + k * n + i];
                ksk += b[KS + i * m + k] * b[Kt + k * n + j];
            }
            Pn[i * n + j] = b[Pp + i * n + j] - a_ij - a_ji + ksk;
        }
    for (Py_ssize_t i = 0; i < n; i++)
        for (Py_ssize_t j = 0; j < i; j++) {
            double a = 0.5 * (Pn[i * n + j] + Pn[j * n + i]);
            Pn[i * n + j] = a;
            Pn[j * n + i] = a;
        }
    *nis_out = nis;
    *ll_out = -0.5 * (nis + logdet + (double)m * log(2.0 * PI));
    return 1;
}

/* Whether o is an aligned, native-order float64 array of nd dimensions (any strides). */
static int takes(PyObject *o, int nd) {
    if (!PyArray_Check(o)) return 0;
    PyArrayObject *a = (PyArrayObject *)o;
    PyArray_Descr *d = PyArray_DESCR(a);
    return PyArray_NDIM(a) == nd && d->type_num == NPY_DOUBLE && PyArray_ISNBO(d->byteorder) &&
           PyArray_ISALIGNED(a);
}

#define AT1(a, i) (*(const double *)(PyArray_BYTES(a) + (i) * PyArray_STRIDES(a)[0]))
#define AT2(a, i, j) \
    (*(const double *)(PyArray_BYTES(a) + (i) * PyArray_STRIDES(a)[0] + (j) * PyArray_STRIDES(a)[1]))

/* A tuple subclass (a named tuple) of these items, built as tuple.__new__(cls, items) does;
 * steals the references. */
static PyObject *named(PyTypeObject *cls, Py_ssize_t k, PyObject **items) {
    PyObject *t = cls->tp_alloc(cls, k);
    if (t == NULL) {
        for (Py_ssize_t i = 0; i < k; i++) Py_XDECREF(items[i]);
        return NULL;
    }
    for (Py_ssize_t i = 0; i < k; i++) PyTuple_SET_ITEM(t, i, items[i]);
    return t;
}

static PyObject *step(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "step(x, P, z, blob, t_ns) takes 5 arguments");
        return NULL;
    }
    if (state_type == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "bind(GaussianState, Update) was not called");
        return NULL;
    }
    PyObject *t_ns = args[4];
    if (!takes(args[0], 1) || !takes(args[1], 2) || !takes(args[2], 1) || !takes(args[3], 1) ||
        !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)args[3]) || !PyArray_ISWRITEABLE((PyArrayObject *)args[3]) ||
        !PyLong_CheckExact(t_ns))
        return PyLong_FromLong(NOT_TAKEN);
    PyArrayObject *x = (PyArrayObject *)args[0], *P = (PyArrayObject *)args[1], *z = (PyArrayObject *)args[2];
    PyArrayObject *ba = (PyArrayObject *)args[3];
    double *b = (double *)PyArray_DATA(ba);
    Py_ssize_t size = PyArray_DIM(ba, 0);
    if (size < HEAD) return PyLong_FromLong(SHAPE);
    Py_ssize_t code = as_index(b[0]), n = as_index(b[1]), m = as_index(b[2]), s = as_index(b[3]);
    if (code < 0 || n < 1 || m < 1 || s < 0) return PyLong_FromLong(SHAPE);
    Py_ssize_t nn = n * n, mm = m * m;
    Py_ssize_t F = HEAD, Q = F + nn, sp = Q + nn, R = sp + s, xp = R + mm;
    Py_ssize_t Pp = xp + n, FP = Pp + nn, H = FP + nn, zh = H + m * n;
    Py_ssize_t work = n + 2 * nn + m * n + 2 * mm + m + 4 * m * n + mm + m; /* compiled_step.work_size */
    if (PyArray_DIM(x, 0) != n || PyArray_DIM(P, 0) != n || PyArray_DIM(P, 1) != n || PyArray_DIM(z, 0) != m ||
        size < xp + work)
        return PyLong_FromLong(SHAPE);
    int finite = 1; /* predict_work */
    for (Py_ssize_t i = 0; i < n; i++) {
        double t = 0.0;
        for (Py_ssize_t k = 0; k < n; k++) t += b[F + i * n + k] * AT1(x, k);
        b[xp + i] = t;
        finite = finite && isfinite(t);
        for (Py_ssize_t j = 0; j < n; j++) {
            t = 0.0;
            for (Py_ssize_t k = 0; k < n; k++) t += b[F + i * n + k] * AT2(P, k, j);
            b[FP + i * n + j] = t;
        }
    }
    for (Py_ssize_t i = 0; i < n; i++)
        for (Py_ssize_t j = 0; j < n; j++) {
            double t = 0.0;
            for (Py_ssize_t k = 0; k < n; k++) t += b[FP + i * n + k] * b[F + j * n + k];
            b[Pp + i * n + j] = t + b[Q + i * n + j];
        }
    int check = (int)(code & CHECK_Z);
    if (!finite && check) return PyLong_FromLong(NONFINITE);
    if (check)
        for (Py_ssize_t i = 0; i < m; i++)
            if (!isfinite(AT1(z, i))) return PyLong_FromLong(BAD_Z);
    int kind = (int)(code >> 2);
    if (!model(kind, sp, b, n, m, xp, H, zh)) return PyLong_FromLong(SHAPE);
    npy_intp dn[2] = {n, n}, dm[2] = {m, m};
    PyObject *items[5] = {NULL, NULL, NULL, NULL, NULL}; /* x+, P+, y, S, then the state */
    items[0] = PyArray_SimpleNew(1, dn, NPY_DOUBLE);
    items[1] = PyArray_SimpleNew(2, dn, NPY_DOUBLE);
    items[2] = PyArray_SimpleNew(1, dm, NPY_DOUBLE);
    items[3] = PyArray_SimpleNew(2, dm, NPY_DOUBLE);
    if (!items[0] || !items[1] || !items[2] || !items[3]) {
        for (int i = 0; i < 4; i++) Py_XDECREF(items[i]);
        return NULL;
    }
    double *xn = (double *)PyArray_DATA((PyArrayObject *)items[0]);
    double *Pn = (double *)PyArray_DATA((PyArrayObject *)items[1]);
    double *y = (double *)PyArray_DATA((PyArrayObject *)items[2]);
    double *S = (double *)PyArray_DATA((PyArrayObject *)items[3]);
    for (Py_ssize_t i = 0; i < m; i++) y[i] = AT1(z, i) - b[zh + i];
    if (kind == KERNEL_RADAR2D) y[1] = wrap(y[1]);
    double nis, ll;
    if (!update(b, n, m, xp, Pp, H, R, zh + m, y, xn, Pn, S, &nis, &ll)) {
        for (int i = 0; i < 4; i++) Py_DECREF(items[i]);
        return PyLong_FromLong(S_NOT_PD);
    }
    Py_INCREF(t_ns);
    PyObject *st[3] = {items[0], items[1], t_ns};
    PyObject *state = named(state_type, 3, st);
    if (state == NULL) {
        Py_DECREF(items[2]);
        Py_DECREF(items[3]);
        return NULL;
    }
    PyObject *up[5] = {state, items[2], items[3], PyFloat_FromDouble(nis), PyFloat_FromDouble(ll)};
    if (!up[3] || !up[4]) {
        for (int i = 0; i < 5; i++) Py_XDECREF(up[i]);
        return NULL;
    }
    return named(update_type, 5, up);
}

static PyObject *bind(PyObject *self, PyObject *args) {
    PyObject *s, *u;
    if (!PyArg_ParseTuple(args, "O!O!:bind", &PyType_Type, &s, &PyType_Type, &u)) return NULL;
    if (!PyType_IsSubtype((PyTypeObject *)s, &PyTuple_Type) || !PyType_IsSubtype((PyTypeObject *)u, &PyTuple_Type)) {
        PyErr_SetString(PyExc_TypeError, "bind takes two named tuple classes");
        return NULL;
    }
    Py_INCREF(s);
    Py_INCREF(u);
    Py_XSETREF(state_type, (PyTypeObject *)s);
    Py_XSETREF(update_type, (PyTypeObject *)u);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"step", (PyCFunction)(void (*)(void))step, METH_FASTCALL,
     "step(x, P, z, blob, t_ns) -> Update | int: compiled_packed.step_packed with its results allocated "
     "and the Update built; an int status where it is not OK (-1: arguments it does not take)."},
    {"bind", bind, METH_VARARGS, "bind(GaussianState, Update): the classes step builds."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_packed_step", NULL, -1, methods};

PyMODINIT_FUNC PyInit__packed_step(void) {
    import_array();
    return PyModule_Create(&module);
}
