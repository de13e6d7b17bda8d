/* The single-state filter calls of fusion.core.single, as a CPython extension.
 *
 *   predict(x, P, FQ, t_ns, check) -> GaussianState | int
 *   update(code, x, P, z, spec, R, t_ns) -> Update | int
 *   step(x, P, z, blob, t_ns) -> Update | int
 *
 * The arithmetic of fusion.core.compiled_step.predict_fq, update_model and of
 * fusion.core.compiled_packed.step_packed, every product and sum in the same order, no fused
 * multiply-add (built with -ffp-contract=off), the same libm calls: the same bits
 * (tests/core/test_single_c.py). What it adds is what a numba call cannot: it takes its
 * arguments without typing each one through a dispatcher, allocates the results, and returns
 * the GaussianState or Update (named tuples, built in place as tuple.__new__ builds them). On a
 * status other than OK it returns the status (an int, compiled_step's codes), and NOT_TAKEN (-1)
 * where an argument is not what the call reads (an array that is not aligned native float64 of
 * the number of dimensions it needs, a time that is not an int): the caller then takes the
 * numba kernel, which reads any layout, or its general path.
 *
 * bind(GaussianState, Update) must be called once first (fusion.core.single does). Holds the GIL
 * throughout, and while the scratch below holds intermediates it calls nothing that could run
 * Python code (numpy's array allocation is not garbage-collected; the named tuples, whose
 * allocation may start a collection and so finalizers, are built after the arithmetic is done),
 * so the scratch is never used by two calls at once.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <math.h>
#include <string.h>

#include "_single.h"


static const double PI = 3.141592653589793;
static const double TWO_PI = 6.283185307179586;

PyTypeObject *state_type = NULL;  /* fusion.core.gaussian.GaussianState */
PyTypeObject *update_type = NULL; /* fusion.core.gaussian.Update */

/* Scratch of predict and update (the step keeps its own in the blob), grown on demand. */
static double *scratch = NULL;
static Py_ssize_t scratch_size = 0;

static double *scratch_of(Py_ssize_t size) {
    if (size > scratch_size) {
        double *p = PyMem_Realloc(scratch, (size_t)size * sizeof(double));
        if (p == NULL) return NULL;
        scratch = p;
        scratch_size = size;
    }
    return scratch;
}

/* compiled_step.work_size(n, m) */
static Py_ssize_t work_size(Py_ssize_t n, Py_ssize_t m) {
    return n + 2 * n * n + m * n + 2 * m * m + m + 4 * m * n + m * m + m;
}

/* A float as an index, as numba's int(): truncated; -1 where it is no index at all. */
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

#define AT1(a, i) (*(const double *)(PyArray_BYTES(a) + (i) * PyArray_STRIDES(a)[0]))
#define AT2(a, i, j) \
    (*(const double *)(PyArray_BYTES(a) + (i) * PyArray_STRIDES(a)[0] + (j) * PyArray_STRIDES(a)[1]))

/* compiled.predict_work: x- = F x into xo, P- = F P F' + Q into Po (F, Q row-major n x n; FP
 * n x n scratch); whether x- is finite. */
static int predict_into(const double *F, const double *Q, PyArrayObject *x, PyArrayObject *P, Py_ssize_t n,
                        double *xo, double *Po, double *FP) {
    int finite = 1;
    for (Py_ssize_t i = 0; i < n; i++) {
        double t = 0.0;
        for (Py_ssize_t k = 0; k < n; k++) t += F[i * n + k] * AT1(x, k);
        xo[i] = t;
        finite = finite && isfinite(t);
        for (Py_ssize_t j = 0; j < n; j++) {
            t = 0.0;
            for (Py_ssize_t k = 0; k < n; k++) t += F[i * n + k] * AT2(P, k, j);
            FP[i * n + j] = t;
        }
    }
    for (Py_ssize_t i = 0; i < n; i++)
        for (Py_ssize_t j = 0; j < n; j++) {
            double t = 0.0;
            for (Py_ssize_t k = 0; k < n; k++) t += FP[i * n + k] * F[j * n + k];
            Po[i * n + j] = t + Q[i * n + j];
        }
    return finite;
}

/* compiled_step._cartesian / _radar2d: h(x) into zh and H (m x n, zeroed first) for the model
 * `kind` with its spec (s floats); 0 where the spec does not fit. */
static int model(int kind, const double *spec, Py_ssize_t s, const double *x, Py_ssize_t n, Py_ssize_t m,
                 double *zh, double *H) {
    for (Py_ssize_t i = 0; i < m * n; i++) H[i] = 0.0;
    if (kind == KERNEL_CARTESIAN) {
        if (s != 2 + 2 * m + m * m || as_index(spec[0]) != n) return 0;
        for (Py_ssize_t i = 0; i < m; i++) {
            Py_ssize_t c = as_index(spec[2 + i]);
            if (!(0 <= c && c < n)) return 0;
        }
        int posed = spec[1] != 0.0;
        Py_ssize_t rot = 2 + 2 * m;
        for (Py_ssize_t j = 0; j < m; j++) {
            if (posed) {
                double t = 0.0;
                for (Py_ssize_t i = 0; i < m; i++) {
                    Py_ssize_t c = as_index(spec[2 + i]);
                    t += (x[c] - spec[2 + m + i]) * spec[rot + i * m + j];
                    H[j * n + c] += spec[rot + i * m + j];
                }
                zh[j] = t;
            } else {
                Py_ssize_t c = as_index(spec[2 + j]);
                zh[j] = x[c];
                H[j * n + c] = 1.0;
            }
        }
        return 1;
    }
    if (kind != KERNEL_RADAR2D) return 0;
    if (s != 8) return 0;
    int rr = spec[7] != 0.0;
    if (m != (rr ? 3 : 2)) return 0;
    Py_ssize_t ix = as_index(spec[3]), iy = as_index(spec[4]), jvx = as_index(spec[5]), jvy = as_index(spec[6]);
    if (!(0 <= ix && ix < n && 0 <= iy && iy < n && 0 <= jvx && jvx < n && 0 <= jvy && jvy < n)) return 0;
    double dx = x[ix] - spec[0];
    double dy = x[iy] - spec[1];
    double r = hypot(dx, dy);
    zh[0] = r;
    zh[1] = wrap(atan2(dy, dx) - spec[2]);
    double r2 = dx * dx + dy * dy;
    double rj = sqrt(r2);
    H[ix] = dx / rj;
    H[iy] = dy / rj;
    H[n + ix] = -dy / r2;
    H[n + iy] = dx / r2;
    if (rr) {
        double vx = x[jvx], vy = x[jvy];
        zh[2] = (dx * vx + dy * vy) / r;
        double cross = vx * dy - vy * dx;
        H[2 * n + ix] = dy * cross / (r2 * rj);
        H[2 * n + iy] = -dx * cross / (r2 * rj);
        H[2 * n + jvx] = dx / rj;
        H[2 * n + jvy] = dy / rj;
    }
    return 1;
}

/* compiled.cholesky_into: S = L L' into the lower triangle of L (m x m); 0 where S is not
 * positive definite. */
static int cholesky(const double *S, double *L, Py_ssize_t m) {
    for (Py_ssize_t j = 0; j < m; j++) {
        double d = S[j * m + j];
        for (Py_ssize_t k = 0; k < j; k++) d -= L[j * m + k] * L[j * m + k];
        if (!(d > 0.0)) return 0;
        L[j * m + j] = sqrt(d);
        for (Py_ssize_t i = j + 1; i < m; i++) {
            double t = S[i * m + j];
            for (Py_ssize_t k = 0; k < j; k++) t -= L[i * m + k] * L[j * m + k];
            L[i * m + j] = t / L[j * m + j];
        }
    }
    return 1;
}

/* compiled.update_work: the Joseph-form update of x-, P- (row-major) with y, H (m x n), R
 * (m x m) into xn, Pn, S; work of 4 m n + m m + m floats; 0 where S is not positive definite. */
static int update_into(const double *xp, const double *Pp, const double *y, const double *H, const double *R,
                       Py_ssize_t n, Py_ssize_t m, double *work, double *xn, double *Pn, double *S,
                       double *nis_out, double *ll_out) {
    Py_ssize_t mn = m * n;
    double *HP = work, *W = work + mn, *Kt = work + 2 * mn, *KS = work + 3 * mn, *L = work + 4 * mn;
    double *w = L + m * m;
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < n; j++) {
            double s = 0.0;
            for (Py_ssize_t k = 0; k < n; k++) s += H[i * n + k] * Pp[k * n + j];
            HP[i * n + j] = s;
        }
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < m; j++) {
            double s = 0.0;
            for (Py_ssize_t k = 0; k < n; k++) s += HP[i * n + k] * H[j * n + k];
            S[i * m + j] = s + R[i * m + j];
        }
    for (Py_ssize_t i = 0; i < m; i++)
        for (Py_ssize_t j = 0; j < i; j++) {
            double a = 0.5 * (S[i * m + j] + S[j * m + i]);
            S[i * m + j] = a;
            S[j * m + i] = a;
        }
    if (!cholesky(S, L, m)) return 0;
    for (Py_ssize_t i = 0; i < m; i++) {
        double lii = L[i * m + i];
        for (Py_ssize_t j = 0; j < n; j++) {
            double s = HP[i * n + j];
            for (Py_ssize_t k = 0; k < i; k++) s -= L[i * m + k] * W[k * n + j];
            W[i * n + j] = s / lii;
        }
        double s = y[i];
        for (Py_ssize_t k = 0; k < i; k++) s -= L[i * m + k] * w[k];
        w[i] = s / lii;
    }
    for (Py_ssize_t i = m - 1; i >= 0; i--) {
        double lii = L[i * m + i];
        for (Py_ssize_t j = 0; j < n; j++) {
            double s = W[i * n + j];
            for (Py_ssize_t k = i + 1; k < m; k++) s -= L[k * m + i] * Kt[k * n + j];
            Kt[i * n + j] = s / lii;
        }
    }
    double nis = 0.0, logdet = 0.0;
    for (Py_ssize_t i = 0; i < m; i++) {
        nis += w[i] * w[i];
        logdet += 2.0 * log(L[i * m + i]);
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        double s = xp[i];
        for (Py_ssize_t k = 0; k < m; k++) s += Kt[k * n + i] * y[k];
        xn[i] = s;
    }
    for (Py_ssize_t i = 0; i < n; i++)
        for (Py_ssize_t j = 0; j < m; j++) {
            double s = 0.0;
            for (Py_ssize_t k = 0; k < m; k++) s += Kt[k * n + i] * S[k * m + j];
            KS[i * m + j] = s;
        }
    for (Py_ssize_t i = 0; i < n; i++)
        for (Py_ssize_t j = 0; j < n; j++) {
            double a_ij = 0.0, a_ji = 0.0, ksk = 0.0;
            for (Py_ssize_t k = 0; k < m; k++) {
                a_ij += Kt[k * n + i] * HP[k * n + j];
                a_ji += Kt[k * n + j] * HP[k * n + i];
                ksk += KS[i * m + k] * Kt[k * n + j];
            }
            Pn[i * n + j] = Pp[i * n + j] - a_ij - a_ji + ksk;
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

static PyObject *status(int s) { return PyLong_FromLong(s); }

/* A tuple subclass (a named tuple) of these items, built as tuple.__new__(cls, items) does;
 * steals the references (also on failure). */
static PyObject *named(PyTypeObject *cls, Py_ssize_t k, PyObject **items) {
    PyObject *t = cls->tp_alloc(cls, k);
    if (t == NULL) {
        for (Py_ssize_t i = 0; i < k; i++) Py_XDECREF(items[i]);
        return NULL;
    }
    for (Py_ssize_t i = 0; i < k; i++) PyTuple_SET_ITEM(t, i, items[i]);
    return t;
}

/* Fresh C-ordered results: x (n,), P (n, n), and with m > 0 y (m,) and S (m, m); 0 on failure
 * (with the error set and nothing left allocated). */
static int fresh(PyObject **out, Py_ssize_t n, Py_ssize_t m) {
    npy_intp dn[2] = {n, n}, dm[2] = {m, m};
    int k = m > 0 ? 4 : 2;
    out[0] = PyArray_SimpleNew(1, dn, NPY_DOUBLE);
    out[1] = PyArray_SimpleNew(2, dn, NPY_DOUBLE);
    out[2] = m > 0 ? PyArray_SimpleNew(1, dm, NPY_DOUBLE) : NULL;
    out[3] = m > 0 ? PyArray_SimpleNew(2, dm, NPY_DOUBLE) : NULL;
    for (int i = 0; i < k; i++)
        if (out[i] == NULL) {
            for (int j = 0; j < 4; j++) Py_CLEAR(out[j]);
            return 0;
        }
    return 1;
}

#define DATA(o) ((double *)PyArray_DATA((PyArrayObject *)(o)))

/* GaussianState(x, P, t_ns), stealing x and P. */
static PyObject *new_state(PyObject *x, PyObject *P, PyObject *t_ns) {
    Py_INCREF(t_ns);
    PyObject *items[3] = {x, P, t_ns};
    return named(state_type, 3, items);
}

/* Update(GaussianState(x, P, t_ns), y, S, nis, ll), stealing r[0..3]. */
static PyObject *new_update(PyObject **r, PyObject *t_ns, double nis, double ll) {
    PyObject *state = new_state(r[0], r[1], t_ns);
    if (state == NULL) {
        Py_DECREF(r[2]);
        Py_DECREF(r[3]);
        return NULL;
    }
    PyObject *items[5] = {state, r[2], r[3], PyFloat_FromDouble(nis), PyFloat_FromDouble(ll)};
    if (items[3] == NULL || items[4] == NULL) {
        for (int i = 0; i < 5; i++) Py_XDECREF(items[i]);
        return NULL;
    }
    return named(update_type, 5, items);
}

static int bound(void) {
    if (state_type != NULL) return 1;
    PyErr_SetString(PyExc_RuntimeError, "bind(GaussianState, Update) was not called");
    return 0;
}

/* predict(x, P, FQ, t_ns, check): compiled_step.predict_fq; the state also where x- is not
 * finite and check is false (as the filter returns it). */
PyObject *single_predict(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "predict(x, P, FQ, t_ns, check) takes 5 arguments");
        return NULL;
    }
    if (!bound()) return NULL;
    if (!takes(args[0], 1) || !takes(args[1], 2) || !takes(args[2], 3) ||
        !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)args[2]) || !PyLong_CheckExact(args[3]))
        return status(NOT_TAKEN);
    int check = PyObject_IsTrue(args[4]);
    if (check < 0) return NULL;
    PyArrayObject *x = (PyArrayObject *)args[0], *P = (PyArrayObject *)args[1], *FQ = (PyArrayObject *)args[2];
    Py_ssize_t n = PyArray_DIM(x, 0);
    if (PyArray_DIM(P, 0) != n || PyArray_DIM(P, 1) != n || PyArray_DIM(FQ, 0) != 2 || PyArray_DIM(FQ, 1) != n ||
        PyArray_DIM(FQ, 2) != n)
        return status(SHAPE);
    double *FP = scratch_of(n * n);
    if (FP == NULL) return PyErr_NoMemory();
    PyObject *r[4] = {NULL, NULL, NULL, NULL};
    if (!fresh(r, n, 0)) return NULL;
    const double *F = (const double *)PyArray_DATA(FQ);
    int finite = predict_into(F, F + n * n, x, P, n, DATA(r[0]), DATA(r[1]), FP);
    if (!finite && check) {
        Py_DECREF(r[0]);
        Py_DECREF(r[1]);
        return status(NONFINITE);
    }
    return new_state(r[0], r[1], args[3]);
}

/* update(code, x, P, z, spec, R, t_ns): compiled_step.update_model. */
PyObject *single_update(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "update(code, x, P, z, spec, R, t_ns) takes 7 arguments");
        return NULL;
    }
    if (!bound()) return NULL;
    if (!PyLong_CheckExact(args[0]) || !takes(args[1], 1) || !takes(args[2], 2) || !takes(args[3], 1) ||
        !takes(args[4], 1) || !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)args[4]) || !takes(args[5], 2) ||
        !PyLong_CheckExact(args[6]))
        return status(NOT_TAKEN);
    long code = PyLong_AsLong(args[0]);
    if (code < 0) return PyErr_Occurred() ? NULL : status(NOT_TAKEN);
    PyArrayObject *x = (PyArrayObject *)args[1], *P = (PyArrayObject *)args[2], *z = (PyArrayObject *)args[3];
    PyArrayObject *sa = (PyArrayObject *)args[4], *Ra = (PyArrayObject *)args[5];
    Py_ssize_t n = PyArray_DIM(x, 0), m = PyArray_DIM(z, 0), s = PyArray_DIM(sa, 0);
    if (m < 1 || PyArray_DIM(Ra, 0) != m || PyArray_DIM(Ra, 1) != m || PyArray_DIM(P, 0) != n ||
        PyArray_DIM(P, 1) != n)
        return status(SHAPE);
    long flags = code & (CHECK_Z | CHECK_R);
    int kind = (int)(code >> 2);
    if (flags & CHECK_Z)
        for (Py_ssize_t i = 0; i < m; i++)
            if (!isfinite(AT1(z, i))) return status(BAD_Z);
    /* scratch: x-, P- (contiguous copies), H, R_s, its factor, h(x), then update_into's work */
    double *b = scratch_of(n + n * n + m * n + 2 * m * m + m + 4 * m * n + m * m + m);
    if (b == NULL) return PyErr_NoMemory();
    double *xc = b, *Pc = xc + n, *H = Pc + n * n, *Rs = H + m * n, *L = Rs + m * m, *zh = L + m * m;
    double *work = zh + m;
    for (Py_ssize_t i = 0; i < n; i++) {
        xc[i] = AT1(x, i);
        for (Py_ssize_t j = 0; j < n; j++) Pc[i * n + j] = AT2(P, i, j);
    }
    if (flags & CHECK_R) { /* compiled_step._checked_R */
        double scale = 1e-300;
        for (Py_ssize_t i = 0; i < m; i++)
            for (Py_ssize_t j = 0; j < m; j++) {
                double v = AT2(Ra, i, j);
                if (!isfinite(v)) return status(BAD_R);
                scale = fmax(scale, fabs(v));
            }
        for (Py_ssize_t i = 0; i < m; i++)
            for (Py_ssize_t j = 0; j < m; j++) {
                double a = AT2(Ra, i, j), t = AT2(Ra, j, i);
                if (fabs(a - t) > 1e-9 * scale) return status(BAD_R);
                Rs[i * m + j] = 0.5 * (a + t);
            }
        if (!cholesky(Rs, L, m)) return status(BAD_R);
    } else {
        for (Py_ssize_t i = 0; i < m; i++)
            for (Py_ssize_t j = 0; j < m; j++) Rs[i * m + j] = AT2(Ra, i, j);
    }
    if (!model(kind, (const double *)PyArray_DATA(sa), s, xc, n, m, zh, H)) return status(SHAPE);
    PyObject *r[4] = {NULL, NULL, NULL, NULL};
    if (!fresh(r, n, m)) return NULL;
    double *y = DATA(r[2]);
    for (Py_ssize_t i = 0; i < m; i++) y[i] = AT1(z, i) - zh[i];
    if (kind == KERNEL_RADAR2D) y[1] = wrap(y[1]);
    double nis, ll;
    if (!update_into(xc, Pc, y, H, Rs, n, m, work, DATA(r[0]), DATA(r[1]), DATA(r[3]), &nis, &ll)) {
        for (int i = 0; i < 4; i++) Py_DECREF(r[i]);
        return status(S_NOT_PD);
    }
    return new_update(r, args[6], nis, ll);
}

/* step(x, P, z, blob, t_ns): compiled_packed.step_packed on its blob (layout in that module). */
PyObject *single_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "step(x, P, z, blob, t_ns) takes 5 arguments");
        return NULL;
    }
    if (!bound()) return NULL;
    PyObject *t_ns = args[4];
    if (!takes(args[0], 1) || !takes(args[1], 2) || !takes(args[2], 1) || !takes(args[3], 1) ||
        !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)args[3]) || !PyArray_ISWRITEABLE((PyArrayObject *)args[3]) ||
        !PyLong_CheckExact(t_ns))
        return status(NOT_TAKEN);
    PyArrayObject *x = (PyArrayObject *)args[0], *P = (PyArrayObject *)args[1], *z = (PyArrayObject *)args[2];
    PyArrayObject *ba = (PyArrayObject *)args[3];
    double *b = (double *)PyArray_DATA(ba);
    Py_ssize_t size = PyArray_DIM(ba, 0);
    if (size < HEAD) return status(SHAPE);
    Py_ssize_t code = as_index(b[0]), n = as_index(b[1]), m = as_index(b[2]), s = as_index(b[3]);
    if (code < 0 || n < 1 || m < 1 || s < 0) return status(SHAPE);
    Py_ssize_t nn = n * n, mm = m * m;
    Py_ssize_t F = HEAD, Q = F + nn, sp = Q + nn, R = sp + s, xp = R + mm;
    Py_ssize_t Pp = xp + n, FP = Pp + nn, H = FP + nn, zh = H + m * n;
    if (PyArray_DIM(x, 0) != n || PyArray_DIM(P, 0) != n || PyArray_DIM(P, 1) != n || PyArray_DIM(z, 0) != m ||
        size < xp + work_size(n, m))
        return status(SHAPE);
    int finite = predict_into(b + F, b + Q, x, P, n, b + xp, b + Pp, b + FP);
    int check = (int)(code & CHECK_Z);
    if (!finite && check) return status(NONFINITE);
    if (check)
        for (Py_ssize_t i = 0; i < m; i++)
            if (!isfinite(AT1(z, i))) return status(BAD_Z);
    int kind = (int)(code >> 2);
    if (!model(kind, b + sp, s, b + xp, n, m, b + zh, b + H)) return status(SHAPE);
    PyObject *r[4] = {NULL, NULL, NULL, NULL};
    if (!fresh(r, n, m)) return NULL;
    double *y = DATA(r[2]);
    for (Py_ssize_t i = 0; i < m; i++) y[i] = AT1(z, i) - b[zh + i];
    if (kind == KERNEL_RADAR2D) y[1] = wrap(y[1]);
    double nis, ll;
    if (!update_into(b + xp, b + Pp, y, b + H, b + R, n, m, b + zh + m, DATA(r[0]), DATA(r[1]), DATA(r[3]), &nis,
                     &ll)) {
        for (int i = 0; i < 4; i++) Py_DECREF(r[i]);
        return status(S_NOT_PD);
    }
    return new_update(r, t_ns, nis, ll);
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
    {"predict", (PyCFunction)(void (*)(void))single_predict, METH_FASTCALL,
     "predict(x, P, FQ, t_ns, check) -> GaussianState | int: compiled_step.predict_fq, its results "
     "allocated and the state built."},
    {"update", (PyCFunction)(void (*)(void))single_update, METH_FASTCALL,
     "update(code, x, P, z, spec, R, t_ns) -> Update | int: compiled_step.update_model, its results "
     "allocated and the Update built."},
    {"step", (PyCFunction)(void (*)(void))single_step, METH_FASTCALL,
     "step(x, P, z, blob, t_ns) -> Update | int: compiled_packed.step_packed, its results allocated "
     "and the Update built."},
    {"bind", bind, METH_VARARGS, "bind(GaussianState, Update): the classes the calls build."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_single", NULL, -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__single(void) {
    import_array();
    PyObject *m = PyModule_Create(&module);
    if (m != NULL && add_filter_calls(m) < 0) Py_CLEAR(m);
    return m;
}
