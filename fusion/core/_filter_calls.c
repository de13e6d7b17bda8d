/* fusion.core._single.FilterCalls: ExtendedKalmanFilter's (and so KalmanFilter's) predict,
 * update and step as C methods, for their call cost.
 *
 *   predict(state, t_ns, *, u=None) -> GaussianState
 *   update(state, z, model, *, R=None) -> Update
 *   step(state, t_ns, z, model, *, R=None, u=None) -> Update
 *
 * Each takes the one case that is most of a filter's calls and makes _single.c's call for it;
 * everything else goes to the filter's own Python method, `_predict_general`, `_update_general`
 * or `_step_general` (fusion.core.kalman), with the arguments as they came:
 *   - predict: no u, a TransitionCache (`_transitions`, a dict dt_s -> FQ) that already holds
 *     FQ for dt_s = d / 10^9 (d = t_ns - state.t_ns, both ints, 0 <= d <= 2^53, so that the
 *     division is Python's d / NS_PER_S to the bit), then predict(x, P, FQ, t_ns, `_check`);
 *   - update: no R, the model's kernel_kind > 0 (and is_linear where `_linear_only`), then
 *     update(kind << 2 | CHECK_Z if `_check`, x, P, z, model.kernel_spec, model.R, state.t_ns);
 *   - step: no R, no u, a step plan for the model (`_plans[model]`, fusion.core.step_plan) made
 *     with the model's R of now (plan.R is model.R) that already holds the blob of d =
 *     t_ns - state.t_ns (ints, d >= 0), then step(x, P, z, plan.blobs[d], t_ns).
 * What such a call returns other than the GaussianState or Update (a status, NOT_TAKEN) also
 * goes to the general method, which makes the same call again and takes numba's twin or the
 * numpy path from there (and raises the typed error): the same results, the same errors as the
 * general methods alone (tests/core/test_filter_calls.py).
 *
 * _transitions, _plans, _check and _linear_only are this type's fields, read and set from Python
 * as attributes (the filter's __init__ and its `check` setter set them).
 */
#include "_single.h"

#include <structmember.h>

typedef struct {
    PyObject_HEAD
    PyObject *transitions; /* a TransitionCache, or NULL/None */
    PyObject *plans;       /* model -> StepPlan (a dict), or NULL/None */
    char check;
    char linear_only;
} FilterCalls;

static PyObject *s_predict_general, *s_update_general, *s_step_general, *s_is_linear, *s_kernel_kind, *s_kernel_spec,
    *s_R;

/* self.<name>(*args, **kwargs) as the method was called. */
static PyObject *general(PyObject *self, PyObject *name, PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    Py_ssize_t nargs = PyVectorcall_NARGS(nargsf);
    Py_ssize_t total = nargs + (kwnames == NULL ? 0 : PyTuple_GET_SIZE(kwnames));
    PyObject *small[8], **stack = small;
    if (total + 1 > 8) {
        stack = PyMem_Malloc((size_t)(total + 1) * sizeof(PyObject *));
        if (stack == NULL) return PyErr_NoMemory();
    }
    stack[0] = self;
    for (Py_ssize_t i = 0; i < total; i++) stack[i + 1] = args[i];
    PyObject *out = PyObject_VectorcallMethod(name, stack, (size_t)(nargs + 1), kwnames);
    if (stack != small) PyMem_Free(stack);
    return out;
}

/* An exact int as a long long; 0 where it is none or out of range. */
static int exact_int(PyObject *o, long long *v) {
    if (!PyLong_CheckExact(o)) return 0;
    int overflow;
    *v = PyLong_AsLongLongAndOverflow(o, &overflow);
    return !overflow;
}

static PyObject *fc_predict(FilterCalls *self, PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    PyObject *cache = self->transitions;
    if (PyVectorcall_NARGS(nargsf) == 2 && kwnames == NULL && state_type != NULL && cache != NULL &&
        PyDict_Check(cache) && Py_TYPE(args[0]) == state_type && PyTuple_GET_SIZE(args[0]) == 3) {
        PyObject *state = args[0], *t_ns = args[1];
        long long t, t0, d;
        if (exact_int(t_ns, &t) && exact_int(PyTuple_GET_ITEM(state, 2), &t0) && !__builtin_sub_overflow(t, t0, &d) &&
            d >= 0 && d <= (1LL << 53)) {
            PyObject *key = PyFloat_FromDouble((double)d / 1e9);
            if (key == NULL) return NULL;
            PyObject *FQ = PyDict_GetItemWithError(cache, key); /* borrowed */
            Py_DECREF(key);
            if (FQ == NULL && PyErr_Occurred()) return NULL;
            if (FQ != NULL) {
                Py_INCREF(FQ);
                PyObject *argv[5] = {PyTuple_GET_ITEM(state, 0), PyTuple_GET_ITEM(state, 1), FQ, t_ns,
                                     self->check ? Py_True : Py_False};
                PyObject *out = single_predict(NULL, argv, 5);
                Py_DECREF(FQ);
                if (out == NULL || Py_TYPE(out) == state_type) return out;
                Py_DECREF(out);
            }
        }
    }
    return general((PyObject *)self, s_predict_general, args, nargsf, kwnames);
}

/* model.<name> as a C long; 0 with no error where it is not an exact int (or missing). */
static int long_attr(PyObject *model, PyObject *name, long *v) {
    PyObject *o = PyObject_GetAttr(model, name);
    if (o == NULL) {
        PyErr_Clear(); /* the general method reads it again and raises */
        return 0;
    }
    int ok = PyLong_CheckExact(o);
    *v = ok ? PyLong_AsLong(o) : 0;
    Py_DECREF(o);
    if (ok && *v == -1 && PyErr_Occurred()) {
        PyErr_Clear();
        return 0;
    }
    return ok;
}

/* The update call for a model with a compiled twin; NULL without an error where it does not
 * apply. */
static PyObject *model_update(FilterCalls *self, PyObject *state, PyObject *z, PyObject *model) {
    if (self->linear_only) {
        PyObject *lin = PyObject_GetAttr(model, s_is_linear);
        int yes = lin == NULL ? -1 : PyObject_IsTrue(lin);
        Py_XDECREF(lin);
        if (yes != 1) {
            PyErr_Clear();
            return NULL;
        }
    }
    long kind;
    if (!long_attr(model, s_kernel_kind, &kind) || kind <= 0 || kind > 255) return NULL;
    PyObject *spec = PyObject_GetAttr(model, s_kernel_spec);
    PyObject *R = spec == NULL ? NULL : PyObject_GetAttr(model, s_R);
    PyObject *code = R == NULL ? NULL : PyLong_FromLong(kind << 2 | (self->check ? CHECK_Z : 0));
    PyObject *out = NULL;
    if (code != NULL) {
        PyObject *argv[7] = {code, PyTuple_GET_ITEM(state, 0), PyTuple_GET_ITEM(state, 1), z, spec, R,
                             PyTuple_GET_ITEM(state, 2)};
        out = single_update(NULL, argv, 7);
    }
    Py_XDECREF(spec);
    Py_XDECREF(R);
    Py_XDECREF(code);
    if (out != NULL && Py_TYPE(out) != update_type) Py_CLEAR(out);
    if (out == NULL) PyErr_Clear(); /* (a failed allocation: the general method meets it again) */
    return out;
}

static PyObject *fc_update(FilterCalls *self, PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    if (PyVectorcall_NARGS(nargsf) == 3 && kwnames == NULL && state_type != NULL &&
        Py_TYPE(args[0]) == state_type && PyTuple_GET_SIZE(args[0]) == 3) {
        PyObject *out = model_update(self, args[0], args[1], args[2]);
        if (out != NULL) return out;
    }
    return general((PyObject *)self, s_update_general, args, nargsf, kwnames);
}

/* The step call on the filter's plan for the model; NULL without an error where it does not
 * apply. StepPlan is a named tuple whose first two fields are blobs (dt_ns -> blob) and R. */
static PyObject *planned_step(FilterCalls *self, PyObject *state, PyObject *t_ns, PyObject *z, PyObject *model) {
    long long t, t0, d;
    if (self->plans == NULL || !PyDict_CheckExact(self->plans) || !exact_int(t_ns, &t) ||
        !exact_int(PyTuple_GET_ITEM(state, 2), &t0) || __builtin_sub_overflow(t, t0, &d) || d < 0)
        return NULL;
    PyObject *plan = PyDict_GetItemWithError(self->plans, model); /* borrowed */
    if (plan == NULL || !PyTuple_Check(plan) || PyTuple_GET_SIZE(plan) < 2 || !PyDict_CheckExact(PyTuple_GET_ITEM(plan, 0))) {
        PyErr_Clear(); /* (a model that cannot be a key: the general method says so) */
        return NULL;
    }
    Py_INCREF(plan);
    PyObject *R = PyObject_GetAttr(model, s_R);
    PyObject *key = R == PyTuple_GET_ITEM(plan, 1) ? PyLong_FromLongLong(d) : NULL;
    PyObject *packed = key == NULL ? NULL : PyDict_GetItemWithError(PyTuple_GET_ITEM(plan, 0), key);
    PyObject *out = NULL;
    if (packed != NULL) {
        Py_INCREF(packed);
        PyObject *argv[5] = {PyTuple_GET_ITEM(state, 0), PyTuple_GET_ITEM(state, 1), z, packed, t_ns};
        out = single_step(NULL, argv, 5);
        Py_DECREF(packed);
    }
    Py_XDECREF(key);
    Py_XDECREF(R);
    Py_DECREF(plan);
    if (out != NULL && Py_TYPE(out) != update_type) Py_CLEAR(out);
    if (out == NULL) PyErr_Clear();
    return out;
}

static PyObject *fc_step(FilterCalls *self, PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    if (PyVectorcall_NARGS(nargsf) == 4 && kwnames == NULL && state_type != NULL &&
        Py_TYPE(args[0]) == state_type && PyTuple_GET_SIZE(args[0]) == 3) {
        PyObject *out = planned_step(self, args[0], args[1], args[2], args[3]);
        if (out != NULL) return out;
    }
    return general((PyObject *)self, s_step_general, args, nargsf, kwnames);
}

static int fc_traverse(FilterCalls *self, visitproc visit, void *arg) {
    Py_VISIT(self->transitions);
    Py_VISIT(self->plans);
    return 0;
}

static int fc_clear(FilterCalls *self) {
    Py_CLEAR(self->transitions);
    Py_CLEAR(self->plans);
    return 0;
}

static void fc_dealloc(FilterCalls *self) {
    PyObject_GC_UnTrack(self);
    fc_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyMethodDef fc_methods[] = {
    {"predict", (PyCFunction)(void (*)(void))fc_predict, METH_FASTCALL | METH_KEYWORDS,
     "predict($self, state, t_ns, *, u=None)\n--\n\n"
     "Predict to t_ns (>= state.t_ns); u is the control input if the model takes one."},
    {"update", (PyCFunction)(void (*)(void))fc_update, METH_FASTCALL | METH_KEYWORDS,
     "update($self, state, z, model, *, R=None)\n--\n\n"
     "Fold z (taken at state.t_ns) in; R defaults to the model's."},
    {"step", (PyCFunction)(void (*)(void))fc_step, METH_FASTCALL | METH_KEYWORDS,
     "step($self, state, t_ns, z, model, *, R=None, u=None)\n--\n\n"
     "Predict to t_ns, then fold z (taken at t_ns) in: update(predict(state, t_ns, u=u), z, model, "
     "R=R), the same Update bit for bit and the same errors."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef fc_members[] = {
    {"_transitions", T_OBJECT, offsetof(FilterCalls, transitions), 0,
     "F(dt) and Q(dt) per dt_s (a TransitionCache), or None"},
    {"_plans", T_OBJECT, offsetof(FilterCalls, plans), 0, "the step plans, per model (a dict), or None"},
    {"_check", T_BOOL, offsetof(FilterCalls, check), 0, "whether inputs are validated"},
    {"_linear_only", T_BOOL, offsetof(FilterCalls, linear_only), 0,
     "whether update refuses a nonlinear measurement model"},
    {NULL, 0, 0, 0, NULL},
};

static PyTypeObject FilterCallsType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "fusion.core._single.FilterCalls",
    .tp_basicsize = sizeof(FilterCalls),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE | Py_TPFLAGS_HAVE_GC,
    .tp_doc = "predict, update and step of ExtendedKalmanFilter as C methods (fusion/core/_filter_calls.c).",
    .tp_new = PyType_GenericNew,
    .tp_traverse = (traverseproc)fc_traverse,
    .tp_clear = (inquiry)fc_clear,
    .tp_dealloc = (destructor)fc_dealloc,
    .tp_methods = fc_methods,
    .tp_members = fc_members,
};

int add_filter_calls(PyObject *module) {
    struct { PyObject **s; const char *name; } names[] = {
        {&s_predict_general, "_predict_general"}, {&s_update_general, "_update_general"},
        {&s_step_general, "_step_general"},
        {&s_is_linear, "is_linear"}, {&s_kernel_kind, "kernel_kind"}, {&s_kernel_spec, "kernel_spec"}, {&s_R, "R"},
    };
    for (size_t i = 0; i < sizeof(names) / sizeof(names[0]); i++)
        if ((*names[i].s = PyUnicode_InternFromString(names[i].name)) == NULL) return -1;
    if (PyType_Ready(&FilterCallsType) < 0) return -1;
    Py_INCREF(&FilterCallsType);
    if (PyModule_AddObject(module, "FilterCalls", (PyObject *)&FilterCallsType) < 0) {
        Py_DECREF(&FilterCallsType);
        return -1;
    }
    return 0;
}
