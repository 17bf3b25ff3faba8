/* Kernels of one mechanism, emitted by cog_id_ros.core.emitter: do not edit. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

static PyObject *record_type[N_KERNELS];

/* n doubles from a sequence of numbers; -1 and a Python error when it is not one */
static int read_doubles(PyObject *seq, double *dst, Py_ssize_t n, const char *name)
{
    PyObject *fast = PySequence_Fast(seq, name);
    if (fast == NULL)
        return -1;
    if (PySequence_Fast_GET_SIZE(fast) != n) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd values, got %zd", name, n,
                     PySequence_Fast_GET_SIZE(fast));
        Py_DECREF(fast);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(fast);
    for (Py_ssize_t i = 0; i < n; i++) {
        dst[i] = PyFloat_AsDouble(items[i]);
        if (dst[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(fast);
            return -1;
        }
    }
    Py_DECREF(fast);
    return 0;
}

/* n_rows sequences of `width` numbers, row after row */
static int read_rows(PyObject *seq, double *dst, Py_ssize_t n_rows, Py_ssize_t width,
                     const char *name)
{
    PyObject *fast = PySequence_Fast(seq, name);
    if (fast == NULL)
        return -1;
    if (PySequence_Fast_GET_SIZE(fast) != n_rows) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd rows, got %zd", name, n_rows,
                     PySequence_Fast_GET_SIZE(fast));
        Py_DECREF(fast);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(fast);
    for (Py_ssize_t i = 0; i < n_rows; i++)
        if (read_doubles(items[i], dst + i * width, width, name) < 0) {
            Py_DECREF(fast);
            return -1;
        }
    Py_DECREF(fast);
    return 0;
}

/* a tuple of n floats */
static PyObject *floats(const double *v, Py_ssize_t n)
{
    PyObject *t = PyTuple_New(n);
    if (t == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *x = PyFloat_FromDouble(v[i]);
        if (x == NULL) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, x);
    }
    return t;
}

/* a tuple of n_rows tuples of `width` floats */
static PyObject *rows(const double *v, Py_ssize_t n_rows, Py_ssize_t width)
{
    PyObject *t = PyTuple_New(n_rows);
    if (t == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < n_rows; i++) {
        PyObject *row = floats(v + i * width, width);
        if (row == NULL) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, row);
    }
    return t;
}

/* the record type's instance (a tuple subclass) of `fields`, which it takes over */
static PyObject *record(int kind, PyObject *fields)
{
    if (fields == NULL)
        return NULL;
    PyObject *args = PyTuple_Pack(1, fields);
    Py_DECREF(fields);
    if (args == NULL)
        return NULL;
    PyObject *out = PyTuple_Type.tp_new((PyTypeObject *)record_type[kind], args, NULL);
    Py_DECREF(args);
    return out;
}

/* the n_views buffers of a *_many call, checked: C-contiguous float64 of N rows of
   width[k]; the last one writable. Returns N, or -1 with a Python error. */
static Py_ssize_t many_buffers(PyObject *const *args, Py_ssize_t nargs, int n_views,
                               const Py_ssize_t *width, Py_buffer *view, const char *name)
{
    if (nargs != n_views) {
        PyErr_Format(PyExc_TypeError, "%s() takes %d arrays", name, n_views);
        return -1;
    }
    Py_ssize_t n = -1;
    for (int k = 0; k < n_views; k++) {
        int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (k == n_views - 1 ? PyBUF_WRITABLE : 0);
        if (PyObject_GetBuffer(args[k], &view[k], flags) < 0) {
            for (int j = 0; j < k; j++)
                PyBuffer_Release(&view[j]);
            return -1;
        }
        Py_ssize_t rows = width[k] ? view[k].len / (Py_ssize_t)sizeof(double) / width[k] : 0;
        if (view[k].itemsize != sizeof(double) || view[k].format == NULL ||
                strcmp(view[k].format, "d") != 0 ||
                (width[k] && rows * width[k] * (Py_ssize_t)sizeof(double) != view[k].len) ||
                (width[k] && n >= 0 && rows != n)) {
            PyErr_Format(PyExc_ValueError, "%s: argument %d must be a C-contiguous float64 "
                         "array of shape (N, %zd)", name, k + 1, width[k]);
            for (int j = 0; j <= k; j++)
                PyBuffer_Release(&view[j]);
            return -1;
        }
        if (width[k])
            n = rows;
    }
    return n < 0 ? 0 : n;
}

static PyObject *set_record_types(PyObject *self, PyObject *args)
{
    for (int i = 0; i < N_KERNELS; i++) {
        PyObject *t = PyTuple_GetItem(args, i);
        if (t == NULL)
            return NULL;
        Py_INCREF(t);
        Py_XSETREF(record_type[i], t);
    }
    Py_RETURN_NONE;
}
