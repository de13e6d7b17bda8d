/* What the two sources of fusion.core._single share: _single.c (the calls of
 * fusion.core.single) and _filter_calls.c (ExtendedKalmanFilter's predict, update and step as
 * C methods, which make those calls). */
#ifndef FUSION_SINGLE_H
#define FUSION_SINGLE_H
#include <Python.h>

/* Shared between the two sources only: hidden, so that no other library's symbol of the same
 * name (a `step` of some library loaded before this one) can take the place of ours. */
#define SHARED __attribute__((visibility("hidden")))

/* compiled_step's status codes, and NOT_TAKEN for arguments a call does not read */
enum { OK = 0, NONFINITE = 1, SHAPE = 2, BAD_Z = 3, BAD_R = 4, S_NOT_PD = 5, NOT_TAKEN = -1 };
enum { CHECK_Z = 1, CHECK_R = 2, HEAD = 4, KERNEL_CARTESIAN = 1, KERNEL_RADAR2D = 2 };

SHARED extern PyTypeObject *state_type;  /* fusion.core.gaussian.GaussianState, once bound */
SHARED extern PyTypeObject *update_type; /* fusion.core.gaussian.Update, once bound */

/* predict(x, P, FQ, t_ns, check), update(code, x, P, z, spec, R, t_ns) and
 * step(x, P, z, blob, t_ns) of _single.c */
SHARED PyObject *single_predict(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
SHARED PyObject *single_update(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
SHARED PyObject *single_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

/* Adds the type FilterCalls to the module; -1 with the error set on failure. */
SHARED int add_filter_calls(PyObject *module);

#endif
