/*
 * native_host: a small FMI co-simulation host in plain C (no Python in it), for FMI 2.0 and 3.0.
 *
 * It loads an extracted FMU's binary with dlopen (binaries/linux64/<modelIdentifier>.so for FMI
 * 2.0, binaries/x86_64-linux/<modelIdentifier>.so for FMI 3.0; the version is the
 * modelDescription's fmiVersion), or, built for Windows with mingw-w64, with LoadLibraryExA
 * (binaries/win64/<id>.dll, binaries/x86_64-windows/<id>.dll), runs it over a fixed communication grid through the FMI C API
 * and writes every output to a CSV file in the FMI cross-check format ("time" first, quoted
 * names, %.17g so that every double is written exactly).
 *
 *   native_host FMU_DIR OUT_CSV [--stop T] [--step H] [--start T0] [--clock ns|multiply] [--in IN_CSV]
 *                               [--set NAME=VALUE]... [--every N] [--refusals] [--threads N] [--also FMU_DIR2]
 *
 * FMU_DIR  the FMU archive extracted (modelDescription.xml, binaries/, resources/).
 * --stop   stop time in s (default: DefaultExperiment stopTime, else 1).
 * --step   communication step in s (default: 1e-3). It is rounded to whole nanoseconds (--clock ns).
 * --start  start time in s (default 0); rounded to whole nanoseconds (--clock ns).
 * --clock  the host's time arithmetic: ns (default), libcosim's grid below; multiply, the plain
 *          fixed-step loop t_k = start + k * step, each step DoStep(t_k, step), nothing rounded.
 * --in     input CSV ("time" first, then one column per input, by name); values between two
 *          rows are linearly interpolated (FMI cross-check rules); a row at the exact grid time
 *          is used as it is.
 * --set    a start value for a parameter or input, by name (Real/Float64 or Integer/Int32).
 * --every N  a row of output every N steps (and after the last), not after every step: a long
 *          run reads its outputs, through the FMU's Python, only where they are written.
 * --refusals  before the run, make every call the project's FMU must refuse (check_refusals)
 *          and require Error from each, then fmi2Reset / fmi3Reset: the run is then that of the
 *          same instance after its reset.
 * --threads N  N instances, each in a thread of its own, each running the whole case and
 *          writing OUT_CSV.1 ... OUT_CSV.N.
 * --also   a second extracted FMU with the same variables (the standalone and the normal FMU of
 *          one model, say), loaded into the same process before either is instantiated; the
 *          same case then runs on it after the first, writing OUT_CSV.also.
 *
 * By default the communication grid is the one of OSP libcosim, which counts time in integer
 * nanoseconds: t_k = (start_ns + k * step_ns) / 1e9 (the double nearest to start + k * step), and
 * the step passed to DoStep is t_{k+1} - t_k. The inputs of step k are those at t_k; they are set
 * before DoStep. Row k of the output is read after the step to t_k (with --every N, every N-th).
 *
 * Any call that returns a status other than OK is an error: the host says which call and which
 * status, and exits with status 1 (so does an FMI 3.0 step that asks to terminate). The FMU's
 * messages go to stderr. The binary is loaded with RTLD_NOW | RTLD_LOCAL into a process that
 * has no Python: the project's FMUs find one themselves (their loader). Exit status: 0 on
 * success, 1 on a usage or FMU error.
 */

#define _XOPEN_SOURCE 700

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

/* What differs on Windows (cross-compiled with mingw-w64): loading the binary, paths, threads. */
#ifdef _WIN32
#include <process.h>
#include <windows.h>
#define PLATFORM2 "win64"
#define PLATFORM3 "x86_64-windows"
#define LIBRARY_SUFFIX ".dll"
#define strtok_r strtok_s
typedef HANDLE Thread;
static void *open_library(const char *path)
{
    return (void *)LoadLibraryExA(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
}
static const char *library_error(void)
{
    static char text[64];
    snprintf(text, sizeof text, "LoadLibraryExA error %lu", (unsigned long)GetLastError());
    return text;
}
static void *library_symbol(void *library, const char *name)
{
    return (void *)GetProcAddress((HMODULE)library, name);
}
static int absolute_path(const char *path, char *out, size_t size)
{
    return _fullpath(out, path, size) != NULL;
}
static int start_thread(Thread *thread, void (*function)(void *), void *argument)
{
    *thread = (HANDLE)_beginthread(function, 0, argument);
    return *thread != (HANDLE)(intptr_t)-1L;
}
static void join_thread(Thread thread)
{
    WaitForSingleObject(thread, INFINITE);
}
#else
#include <dlfcn.h>
#include <pthread.h>
#include <unistd.h>
#define PLATFORM2 "linux64"
#define PLATFORM3 "x86_64-linux"
#define LIBRARY_SUFFIX ".so"
typedef pthread_t Thread;
static void *open_library(const char *path)
{
    return dlopen(path, RTLD_NOW | RTLD_LOCAL);
}
static const char *library_error(void)
{
    return dlerror();
}
static void *library_symbol(void *library, const char *name)
{
    return dlsym(library, name);
}
static int absolute_path(const char *path, char *out, size_t size)
{
    char resolved[PATH_MAX];
    return realpath(path, resolved) && (size_t)snprintf(out, size, "%s", resolved) < size;
}
typedef struct {
    void (*function)(void *);
    void *argument;
} ThreadStart;
static void *thread_main(void *start)
{
    ThreadStart *s = start;
    s->function(s->argument);
    free(s);
    return NULL;
}
static int start_thread(Thread *thread, void (*function)(void *), void *argument)
{
    ThreadStart *s = malloc(sizeof *s);
    if (!s) return 0;
    *s = (ThreadStart){function, argument};
    return pthread_create(thread, NULL, thread_main, s) == 0;
}
static void join_thread(Thread thread)
{
    pthread_join(thread, NULL);
}
#endif

#define MAX_VARS 512
#define MAX_SETS 64
#define MAX_INPUT_COLS 64
#define MAX_THREADS 8

typedef struct {
    char name[128];
    unsigned int vr;
    char causality[16];
    char type[16]; /* "Real" (FMI 3.0 Float64), "Integer" (Int32), or the type's own name */
} Variable;

typedef struct {
    Variable vars[MAX_VARS];
    int n;
    int fmi_version; /* 2 or 3 */
    char guid[128];  /* FMI 3.0: the instantiationToken */
    char model_identifier[128];
    double default_stop;
    int has_default_stop;
} ModelDescription;

typedef struct {
    int ncols;            /* input columns (without time) */
    int var_index[MAX_INPUT_COLS];
    size_t nrows;
    double *time;         /* nrows */
    double *values;       /* nrows * ncols, row-major */
} InputTable;

/* Leave the process without running exit-time destructors: a pythonfmu binary that started its own
 * interpreter finalizes it then (Py_Finalize, on its own thread), which crashes now and then in
 * scipy's _uarray module (a use-after-free in its module teardown), and the binary's fini function
 * releases a static shared_ptr that its exit handler has already destroyed. All output is flushed
 * first; the operating system reclaims the rest. */
static void leave(int status)
{
    fflush(NULL);
    _exit(status);
}

static void die(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "native_host: ");
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "\n");
    va_end(ap);
    leave(1);
}

static char *read_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) die("cannot open %s: %s", path, strerror(errno));
    if (fseek(f, 0, SEEK_END) != 0) die("cannot seek %s", path);
    long size = ftell(f);
    if (size < 0) die("cannot size %s", path);
    rewind(f);
    char *text = malloc((size_t)size + 1);
    if (!text) die("out of memory");
    if (fread(text, 1, (size_t)size, f) != (size_t)size) die("cannot read %s", path);
    text[size] = '\0';
    fclose(f);
    return text;
}

/* The value of attribute `name` in the tag that starts at `tag` (up to its '>'). */
static int attribute(const char *tag, const char *name, char *out, size_t out_size)
{
    const char *end = strchr(tag, '>');
    size_t len = strlen(name);
    for (const char *p = tag; p && (!end || p < end); p++) {
        p = strstr(p, name);
        if (!p || (end && p >= end)) return 0;
        if ((p[-1] == ' ' || p[-1] == '\n' || p[-1] == '\t') && p[len] == '=' && p[len + 1] == '"') {
            const char *value = p + len + 2;
            const char *close = strchr(value, '"');
            if (!close) return 0;
            size_t n = (size_t)(close - value);
            if (n >= out_size) n = out_size - 1;
            memcpy(out, value, n);
            out[n] = '\0';
            return 1;
        }
    }
    return 0;
}

/* The FMI type element of a variable (FMI 2.0: the child of ScalarVariable, FMI 3.0: the
 * variable's own element) that starts at p, if it is one of `types`. */
static const char *type_at(const char *p, const char *const types[], size_t ntypes)
{
    for (size_t i = 0; i < ntypes; i++) {
        size_t n = strlen(types[i]);
        if (p[0] == '<' && strncmp(p + 1, types[i], n) == 0 && strchr(" \t\r\n/>", p[n + 1])) return types[i];
    }
    return NULL;
}

static void read_variable(const char *tag, const char *type, Variable *v)
{
    char vr[32];
    if (!attribute(tag, "name", v->name, sizeof v->name) || !attribute(tag, "valueReference", vr, sizeof vr))
        die("a variable without name or valueReference");
    v->vr = (unsigned int)strtoul(vr, NULL, 10);
    if (!attribute(tag, "causality", v->causality, sizeof v->causality)) strcpy(v->causality, "local");
    snprintf(v->type, sizeof v->type, "%s", type);
}

static void parse_model_description(const char *fmu_dir, ModelDescription *md)
{
    char path[PATH_MAX];
    snprintf(path, sizeof path, "%s/modelDescription.xml", fmu_dir);
    char *xml = read_file(path);
    memset(md, 0, sizeof *md);

    const char *root = strstr(xml, "<fmiModelDescription");
    char version[16];
    if (!root || !attribute(root, "fmiVersion", version, sizeof version)) die("no fmiVersion in %s", path);
    md->fmi_version = strncmp(version, "3.", 2) == 0 ? 3 : strcmp(version, "2.0") == 0 ? 2 : 0;
    if (!md->fmi_version) die("%s: FMI version %s (this host runs 2.0 and 3.0)", path, version);
    if (!attribute(root, md->fmi_version == 2 ? "guid" : "instantiationToken", md->guid, sizeof md->guid))
        die("no %s in %s", md->fmi_version == 2 ? "guid" : "instantiationToken", path);
    const char *cs = strstr(xml, "<CoSimulation");
    if (!cs || !attribute(cs, "modelIdentifier", md->model_identifier, sizeof md->model_identifier))
        die("%s declares no CoSimulation modelIdentifier", path);
    const char *de = strstr(xml, "<DefaultExperiment");
    char buffer[64];
    if (de && attribute(de, "stopTime", buffer, sizeof buffer)) {
        md->default_stop = strtod(buffer, NULL);
        md->has_default_stop = 1;
    }

    if (md->fmi_version == 2) {
        const char *types[] = {"Real", "Integer", "Boolean", "String", "Enumeration"};
        for (const char *p = strstr(xml, "<ScalarVariable"); p; p = strstr(p + 1, "<ScalarVariable")) {
            if (md->n == MAX_VARS) die("more than %d variables", MAX_VARS);
            const char *body = strchr(p, '>');
            const char *q = body ? body + 1 : p;
            while (*q == ' ' || *q == '\n' || *q == '\r' || *q == '\t') q++;
            const char *type = body ? type_at(q, types, sizeof types / sizeof *types) : NULL;
            char name[128] = "?";
            attribute(p, "name", name, sizeof name);
            if (!type) die("variable %s has no type element", name);
            read_variable(p, strcmp(type, "Enumeration") == 0 ? "Integer" : type, &md->vars[md->n++]);
        }
    } else {
        const char *types[] = {"Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32",
                               "Int64", "UInt64", "Boolean", "String", "Binary", "Clock", "Enumeration"};
        const char *begin = strstr(xml, "<ModelVariables"), *end = begin ? strstr(begin, "</ModelVariables>") : NULL;
        for (const char *p = begin; p && p < end; p = strchr(p + 1, '<')) {
            const char *type = type_at(p, types, sizeof types / sizeof *types);
            if (!type) continue;
            if (md->n == MAX_VARS) die("more than %d variables", MAX_VARS);
            const char *kind = strcmp(type, "Float64") == 0 ? "Real" : strcmp(type, "Int32") == 0 ? "Integer" : type;
            read_variable(p, kind, &md->vars[md->n++]);
        }
    }
    free(xml);
}

static int find_variable(const ModelDescription *md, const char *name)
{
    for (int i = 0; i < md->n; i++)
        if (strcmp(md->vars[i].name, name) == 0) return i;
    return -1;
}

/* One CSV field: strip spaces and double quotes. */
static char *trim_field(char *s)
{
    while (*s == ' ' || *s == '"') s++;
    char *e = s + strlen(s);
    while (e > s && (e[-1] == ' ' || e[-1] == '"' || e[-1] == '\n' || e[-1] == '\r')) *--e = '\0';
    return s;
}

static void read_inputs(const char *path, const ModelDescription *md, InputTable *in)
{
    char *text = read_file(path);
    memset(in, 0, sizeof *in);
    char *save = NULL;
    char *line = strtok_r(text, "\n", &save);
    if (!line) die("%s is empty", path);

    /* header */
    char *fsave = NULL;
    int col = 0;
    for (char *f = strtok_r(line, ",", &fsave); f; f = strtok_r(NULL, ",", &fsave), col++) {
        char *name = trim_field(f);
        if (col == 0) {
            if (strcmp(name, "time") != 0) die("%s: the first column must be \"time\"", path);
            continue;
        }
        if (in->ncols == MAX_INPUT_COLS) die("%s: too many columns", path);
        int index = find_variable(md, name);
        if (index < 0 || strcmp(md->vars[index].causality, "input") != 0)
            die("%s: \"%s\" is not an input of the FMU", path, name);
        if (strcmp(md->vars[index].type, "Real") != 0) die("%s: input %s is not Real/Float64", path, name);
        in->var_index[in->ncols++] = index;
    }

    size_t capacity = 1024;
    in->time = malloc(capacity * sizeof(double));
    in->values = malloc(capacity * (size_t)in->ncols * sizeof(double));
    while ((line = strtok_r(NULL, "\n", &save)) != NULL) {
        if (strspn(line, " \r\t") == strlen(line)) continue;
        if (in->nrows == capacity) {
            capacity *= 2;
            in->time = realloc(in->time, capacity * sizeof(double));
            in->values = realloc(in->values, capacity * (size_t)in->ncols * sizeof(double));
        }
        if (!in->time || !in->values) die("out of memory");
        char *end;
        fsave = NULL;
        col = 0;
        for (char *f = strtok_r(line, ",", &fsave); f; f = strtok_r(NULL, ",", &fsave), col++) {
            if (col > in->ncols) die("%s: too many fields in row %zu", path, in->nrows + 1);
            double value = strtod(f, &end); /* strtod is correctly rounded in glibc */
            if (end == f) die("%s: not a number in row %zu", path, in->nrows + 1);
            if (col == 0) in->time[in->nrows] = value;
            else in->values[in->nrows * (size_t)in->ncols + (size_t)(col - 1)] = value;
        }
        if (col != in->ncols + 1) die("%s: too few fields in row %zu", path, in->nrows + 1);
        if (in->nrows > 0 && in->time[in->nrows] < in->time[in->nrows - 1])
            die("%s: time decreases at row %zu", path, in->nrows + 1);
        in->nrows++;
    }
    if (in->nrows == 0) die("%s has no data", path);
    free(text);
}

/* Input column `c` at time t: the row at t exactly, else linear interpolation, held at the ends. */
static double input_at(const InputTable *in, int c, double t)
{
    size_t lo = 0, hi = in->nrows;
    while (lo < hi) { /* first row with time >= t */
        size_t mid = lo + (hi - lo) / 2;
        if (in->time[mid] < t) lo = mid + 1; else hi = mid;
    }
    if (lo < in->nrows && in->time[lo] == t) {
        while (lo + 1 < in->nrows && in->time[lo + 1] == t) lo++; /* right value at an event */
        return in->values[lo * (size_t)in->ncols + (size_t)c];
    }
    if (lo == 0) return in->values[(size_t)c];
    if (lo == in->nrows) return in->values[(in->nrows - 1) * (size_t)in->ncols + (size_t)c];
    double t0 = in->time[lo - 1], t1 = in->time[lo];
    double v0 = in->values[(lo - 1) * (size_t)in->ncols + (size_t)c];
    double v1 = in->values[lo * (size_t)in->ncols + (size_t)c];
    double w0 = (t1 - t) / (t1 - t0);
    return w0 * v0 + (1.0 - w0) * v1;
}

static const char *status_name(int status)
{
    static const char *const names[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};
    return status >= 0 && status < 6 ? names[status] : "unknown";
}

static void logger2(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                    fmi2String category, fmi2String message, ...)
{
    (void)env;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%s] %s (%s): ", instance ? instance : "?", category ? category : "", status_name(status));
    vfprintf(stderr, message, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    fprintf(stderr, "[native_host] %s (%s): %s\n", category ? category : "", status_name(status),
            message ? message : "");
}

static void *symbol(void *lib, const char *name)
{
    void *s = library_symbol(lib, name);
    if (!s) die("the FMU binary has no %s", name);
    return s;
}

/* Anything but OK is an error. */
static void check(int status, const char *what)
{
    if (status != 0) die("%s returned %s (%d)", what, status_name(status), status);
}

/* The FMU's co-simulation interface, whichever its FMI version. */
typedef struct {
    int version;
    void *c; /* the instance */
    fmi2SetRealTYPE *set_real2;
    fmi2SetIntegerTYPE *set_integer2;
    fmi2GetRealTYPE *get_real2;
    fmi2GetIntegerTYPE *get_integer2;
    fmi2SetupExperimentTYPE *setup2;
    fmi2EnterInitializationModeTYPE *enter_init2;
    fmi2ExitInitializationModeTYPE *exit_init2;
    fmi2DoStepTYPE *do_step2;
    fmi2TerminateTYPE *terminate2;
    fmi2ResetTYPE *reset2;
    fmi2FreeInstanceTYPE *free2;
    fmi3SetFloat64TYPE *set_real3;
    fmi3SetInt32TYPE *set_integer3;
    fmi3GetFloat64TYPE *get_real3;
    fmi3GetInt32TYPE *get_integer3;
    fmi3EnterInitializationModeTYPE *enter_init3;
    fmi3ExitInitializationModeTYPE *exit_init3;
    fmi3DoStepTYPE *do_step3;
    fmi3TerminateTYPE *terminate3;
    fmi3ResetTYPE *reset3;
    fmi3FreeInstanceTYPE *free3;
} Fmu;

static void instantiate(Fmu *fmu, void *lib, const ModelDescription *md, const char *abs_dir)
{
    char resources[PATH_MAX + 32];
    fmu->version = md->fmi_version;
    if (fmu->version == 2) {
        fmi2GetVersionTYPE *get_version = (fmi2GetVersionTYPE *)symbol(lib, "fmi2GetVersion");
        if (strcmp(get_version(), "2.0") != 0) die("the binary implements FMI %s, not 2.0", get_version());
        fmu->set_real2 = (fmi2SetRealTYPE *)symbol(lib, "fmi2SetReal");
        fmu->set_integer2 = (fmi2SetIntegerTYPE *)symbol(lib, "fmi2SetInteger");
        fmu->get_real2 = (fmi2GetRealTYPE *)symbol(lib, "fmi2GetReal");
        fmu->get_integer2 = (fmi2GetIntegerTYPE *)symbol(lib, "fmi2GetInteger");
        fmu->setup2 = (fmi2SetupExperimentTYPE *)symbol(lib, "fmi2SetupExperiment");
        fmu->enter_init2 = (fmi2EnterInitializationModeTYPE *)symbol(lib, "fmi2EnterInitializationMode");
        fmu->exit_init2 = (fmi2ExitInitializationModeTYPE *)symbol(lib, "fmi2ExitInitializationMode");
        fmu->do_step2 = (fmi2DoStepTYPE *)symbol(lib, "fmi2DoStep");
        fmu->terminate2 = (fmi2TerminateTYPE *)symbol(lib, "fmi2Terminate");
        fmu->reset2 = (fmi2ResetTYPE *)symbol(lib, "fmi2Reset");
        fmu->free2 = (fmi2FreeInstanceTYPE *)symbol(lib, "fmi2FreeInstance");
        fmi2InstantiateTYPE *instantiate2 = (fmi2InstantiateTYPE *)symbol(lib, "fmi2Instantiate");
        static fmi2CallbackFunctions callbacks = {logger2, calloc, free, NULL, NULL};
        /* a file URI: file:///C:/... on Windows, file:///home/... elsewhere */
        snprintf(resources, sizeof resources, "file://%s%s/resources", abs_dir[0] == '/' ? "" : "/", abs_dir);
        for (char *p = resources; *p; p++)
            if (*p == '\\') *p = '/';
        fmu->c = instantiate2("native_host", fmi2CoSimulation, md->guid, resources, &callbacks, fmi2False, fmi2True);
    } else {
        fmi3GetVersionTYPE *get_version = (fmi3GetVersionTYPE *)symbol(lib, "fmi3GetVersion");
        if (strncmp(get_version(), "3.", 2) != 0) die("the binary implements FMI %s, not 3.0", get_version());
        fmu->set_real3 = (fmi3SetFloat64TYPE *)symbol(lib, "fmi3SetFloat64");
        fmu->set_integer3 = (fmi3SetInt32TYPE *)symbol(lib, "fmi3SetInt32");
        fmu->get_real3 = (fmi3GetFloat64TYPE *)symbol(lib, "fmi3GetFloat64");
        fmu->get_integer3 = (fmi3GetInt32TYPE *)symbol(lib, "fmi3GetInt32");
        fmu->enter_init3 = (fmi3EnterInitializationModeTYPE *)symbol(lib, "fmi3EnterInitializationMode");
        fmu->exit_init3 = (fmi3ExitInitializationModeTYPE *)symbol(lib, "fmi3ExitInitializationMode");
        fmu->do_step3 = (fmi3DoStepTYPE *)symbol(lib, "fmi3DoStep");
        fmu->terminate3 = (fmi3TerminateTYPE *)symbol(lib, "fmi3Terminate");
        fmu->reset3 = (fmi3ResetTYPE *)symbol(lib, "fmi3Reset");
        fmu->free3 = (fmi3FreeInstanceTYPE *)symbol(lib, "fmi3FreeInstance");
        fmi3InstantiateCoSimulationTYPE *instantiate3 =
            (fmi3InstantiateCoSimulationTYPE *)symbol(lib, "fmi3InstantiateCoSimulation");
        snprintf(resources, sizeof resources, "%s%cresources%c", abs_dir, abs_dir[0] == '/' ? '/' : '\\',
                 abs_dir[0] == '/' ? '/' : '\\');
        fmu->c = instantiate3("native_host", md->guid, resources, fmi3False, fmi3True, fmi3False, fmi3False, NULL, 0,
                              NULL, logger3, NULL);
    }
    if (!fmu->c) die("fmi%dInstantiate%s failed", fmu->version, fmu->version == 3 ? "CoSimulation" : "");
}

static int set_real_status(const Fmu *fmu, unsigned int vr, double value)
{
    if (fmu->version == 2) {
        fmi2ValueReference r = vr;
        return fmu->set_real2(fmu->c, &r, 1, &value);
    }
    fmi3ValueReference r = vr;
    return fmu->set_real3(fmu->c, &r, 1, &value, 1);
}

static int set_integer_status(const Fmu *fmu, unsigned int vr, int value)
{
    if (fmu->version == 2) {
        fmi2ValueReference r = vr;
        fmi2Integer v = value;
        return fmu->set_integer2(fmu->c, &r, 1, &v);
    }
    fmi3ValueReference r = vr;
    fmi3Int32 v = value;
    return fmu->set_integer3(fmu->c, &r, 1, &v, 1);
}

static int get_real_status(const Fmu *fmu, unsigned int vr, double *value)
{
    if (fmu->version == 2) {
        fmi2ValueReference r = vr;
        return fmu->get_real2(fmu->c, &r, 1, value);
    }
    fmi3ValueReference r = vr;
    return fmu->get_real3(fmu->c, &r, 1, value, 1);
}

static int get_integer_status(const Fmu *fmu, unsigned int vr, int *value)
{
    int status;
    if (fmu->version == 2) {
        fmi2ValueReference r = vr;
        fmi2Integer v = 0;
        status = fmu->get_integer2(fmu->c, &r, 1, &v);
        *value = (int)v;
    } else {
        fmi3ValueReference r = vr;
        fmi3Int32 v = 0;
        status = fmu->get_integer3(fmu->c, &r, 1, &v, 1);
        *value = (int)v;
    }
    return status;
}

static int do_step_status(const Fmu *fmu, double t, double h, int *terminate)
{
    *terminate = 0;
    if (fmu->version == 2) return fmu->do_step2(fmu->c, t, h, fmi2True);
    fmi3Boolean event = fmi3False, stop = fmi3False, early = fmi3False;
    fmi3Float64 last = t;
    int status = fmu->do_step3(fmu->c, t, h, fmi3True, &event, &stop, &early, &last);
    *terminate = stop;
    return status;
}

static void set_real(const Fmu *fmu, unsigned int vr, double value, const char *what)
{
    check(set_real_status(fmu, vr, value), what);
}

static void set_integer(const Fmu *fmu, unsigned int vr, int value, const char *what)
{
    check(set_integer_status(fmu, vr, value), what);
}

static double get_real(const Fmu *fmu, unsigned int vr)
{
    double value;
    check(get_real_status(fmu, vr, &value), fmu->version == 2 ? "fmi2GetReal" : "fmi3GetFloat64");
    return value;
}

static int get_integer(const Fmu *fmu, unsigned int vr)
{
    int value;
    check(get_integer_status(fmu, vr, &value), fmu->version == 2 ? "fmi2GetInteger" : "fmi3GetInt32");
    return value;
}

static void set_inputs(const Fmu *fmu, const InputTable *inputs, const ModelDescription *md, double t)
{
    for (int col = 0; col < inputs->ncols; col++)
        set_real(fmu, md->vars[inputs->var_index[col]].vr, input_at(inputs, col, t), "setting an input");
}

static int enter_initialization(const Fmu *fmu, double start, double stop)
{
    if (fmu->version == 2) {
        int status = fmu->setup2(fmu->c, fmi2False, 0.0, start, fmi2True, stop);
        return status != 0 ? status : (int)fmu->enter_init2(fmu->c);
    }
    return fmu->enter_init3(fmu->c, fmi3False, 0.0, start, fmi3True, stop);
}

static int exit_initialization(const Fmu *fmu)
{
    return fmu->version == 2 ? (int)fmu->exit_init2(fmu->c) : (int)fmu->exit_init3(fmu->c);
}

static void initialize(const Fmu *fmu, double start, double stop, const InputTable *inputs,
                       const ModelDescription *md)
{
    set_inputs(fmu, inputs, md, start);
    check(enter_initialization(fmu, start, stop), fmu->version == 2 ? "fmi2SetupExperiment, fmi2EnterInitializationMode"
                                                                     : "fmi3EnterInitializationMode");
    check(exit_initialization(fmu), fmu->version == 2 ? "fmi2ExitInitializationMode" : "fmi3ExitInitializationMode");
}

static void do_step(const Fmu *fmu, double t, double h)
{
    int terminate;
    check(do_step_status(fmu, t, h, &terminate), fmu->version == 2 ? "fmi2DoStep" : "fmi3DoStep");
    if (terminate) die("fmi3DoStep at t = %.17g asked to terminate the simulation", t);
}

static void reset(const Fmu *fmu)
{
    check(fmu->version == 2 ? fmu->reset2(fmu->c) : fmu->reset3(fmu->c), fmu->version == 2 ? "fmi2Reset" : "fmi3Reset");
}

static void finish(const Fmu *fmu)
{
    if (fmu->version == 2) {
        check(fmu->terminate2(fmu->c), "fmi2Terminate");
        fmu->free2(fmu->c);
    } else {
        check(fmu->terminate3(fmu->c), "fmi3Terminate");
        fmu->free3(fmu->c);
    }
}

/* -- --refusals: every call the FMU must refuse, each returning Error ------------------------------ */

static void refused(int status, const char *what)
{
    if (status != 3) die("%s returned %s (%d), not Error", what, status_name(status), status);
    fprintf(stderr, "native_host: refused as it must be (Error): %s\n", what);
}

static unsigned int vr_of(const ModelDescription *md, const char *name)
{
    int index = find_variable(md, name);
    if (index < 0) die("--refusals: the FMU has no variable %s", name);
    return md->vars[index].vr;
}

/* The project's FMU's refusals, by its variables' names (m: a parameter in (0, inf) kg,
 * base_velocity: an input, impact_count: an Integer output, main_displacement: a Real one):
 * bad values and wrong types or references in both modes, invalid start values, bad steps, a
 * fixed parameter after initialization, then fmi2Reset / fmi3Reset. */
static void check_refusals(const Fmu *fmu, const ModelDescription *md, double start, double stop)
{
    unsigned int m = vr_of(md, "m"), input = vr_of(md, "base_velocity"), count = vr_of(md, "impact_count");
    unsigned int output = vr_of(md, "main_displacement"), missing = 1000000;
    double real;
    int integer, terminate;
    refused(set_real_status(fmu, m, NAN), "setting m = nan");
    refused(set_real_status(fmu, m, INFINITY), "setting m = inf");
    refused(set_real_status(fmu, input, NAN), "setting base_velocity = nan");
    refused(set_integer_status(fmu, m, 1), "setting the Real m as an Integer");
    refused(set_real_status(fmu, count, 1.0), "setting the Integer impact_count as a Real");
    refused(set_real_status(fmu, missing, 1.0), "setting value reference 1000000");
    refused(get_real_status(fmu, count, &real), "getting the Integer impact_count as a Real");
    refused(get_integer_status(fmu, output, &integer), "getting the Real main_displacement as an Integer");
    refused(get_real_status(fmu, missing, &real), "getting value reference 1000000");
    check(set_real_status(fmu, m, -1.0), "setting m = -1 (checked at the end of initialization)");
    check(enter_initialization(fmu, start, stop), "entering initialization with m = -1");
    refused(exit_initialization(fmu), "exiting initialization with m = -1");
    reset(fmu);
    check(enter_initialization(fmu, start, stop), "entering initialization");
    check(exit_initialization(fmu), "exiting initialization");
    refused(do_step_status(fmu, start, -1e-3, &terminate), "a step of size -1e-3 s");
    refused(do_step_status(fmu, start, 0.0, &terminate), "a step of size 0 s");
    refused(do_step_status(fmu, start + 0.5, 1e-3, &terminate), "a step from a time that does not continue");
    refused(set_real_status(fmu, input, INFINITY), "setting base_velocity = inf while stepping");
    refused(get_real_status(fmu, count, &real), "getting the Integer impact_count as a Real while stepping");
    refused(set_real_status(fmu, m, 0.5), "setting the fixed parameter m = 0.5 after initialization");
    reset(fmu);
}

/* -- one run --------------------------------------------------------------------------------------- */

static void write_row(FILE *out, const Fmu *fmu, const ModelDescription *md, const int *outputs, int nout, double t)
{
    fprintf(out, "%.17g", t);
    for (int j = 0; j < nout; j++) {
        const Variable *v = &md->vars[outputs[j]];
        if (v->type[0] == 'R') fprintf(out, ",%.17g", get_real(fmu, v->vr));
        else fprintf(out, ",%d", get_integer(fmu, v->vr));
    }
    fprintf(out, "\n");
}

typedef struct {
    const ModelDescription *md;
    void *lib;
    const char *abs_dir;
    char out_path[PATH_MAX + 16];
    const char *const *sets;
    int nsets;
    const InputTable *inputs;
    double start, stop, step;
    long long step_ns, nsteps;
    long long every;
    int refusals, multiply; /* multiply: --clock multiply (t_k = start + k * step), else nanoseconds */
} Run;

/* The host's time t_k (--clock). */
static double grid_time(const Run *run, long long start_ns, long long k)
{
    return run->multiply ? run->start + (double)k * run->step : (double)(start_ns + k * run->step_ns) / 1e9;
}

/* Instantiate, (check the refusals,) set the start values, run the grid, write the CSV, free. */
static void simulate(void *argument)
{
    const Run *run = argument;
    const ModelDescription *md = run->md;
    Fmu fmu = {0};
    instantiate(&fmu, run->lib, md, run->abs_dir);
    long long start_ns = run->multiply ? 0 : llround(run->start * 1e9);
    double t = grid_time(run, start_ns, 0);
    if (run->refusals) check_refusals(&fmu, md, t, run->stop);

    for (int i = 0; i < run->nsets; i++) {
        char name[256], what[300];
        const char *set = run->sets[i], *eq = strchr(set, '=');
        if (!eq || (size_t)(eq - set) >= sizeof name) die("--set %s: expected NAME=VALUE", set);
        memcpy(name, set, (size_t)(eq - set));
        name[eq - set] = '\0';
        int index = find_variable(md, name);
        if (index < 0) die("--set: the FMU has no variable %s", name);
        snprintf(what, sizeof what, "setting %s = %s", name, eq + 1);
        if (strcmp(md->vars[index].type, "Real") == 0) set_real(&fmu, md->vars[index].vr, strtod(eq + 1, NULL), what);
        else if (strcmp(md->vars[index].type, "Integer") == 0)
            set_integer(&fmu, md->vars[index].vr, (int)strtol(eq + 1, NULL, 10), what);
        else die("--set %s: only Real/Float64 and Integer/Int32 variables", name);
    }

    /* the outputs, in model order */
    int outputs[MAX_VARS], nout = 0;
    for (int i = 0; i < md->n; i++)
        if (strcmp(md->vars[i].causality, "output") == 0) {
            if (strcmp(md->vars[i].type, "Real") != 0 && strcmp(md->vars[i].type, "Integer") != 0)
                die("output %s is neither Real/Float64 nor Integer/Int32", md->vars[i].name);
            outputs[nout++] = i;
        }

    FILE *out = fopen(run->out_path, "w");
    if (!out) die("cannot write %s: %s", run->out_path, strerror(errno));
    fprintf(out, "\"time\"");
    for (int j = 0; j < nout; j++) fprintf(out, ",\"%s\"", md->vars[outputs[j]].name);
    fprintf(out, "\n");

    initialize(&fmu, t, run->stop, run->inputs, md);
    write_row(out, &fmu, md, outputs, nout, t);
    for (long long k = 0; k < run->nsteps; k++) {
        double t_next = grid_time(run, start_ns, k + 1);
        set_inputs(&fmu, run->inputs, md, t);
        do_step(&fmu, t, run->multiply ? run->step : t_next - t);
        t = t_next;
        if ((k + 1) % run->every == 0 || k + 1 == run->nsteps) write_row(out, &fmu, md, outputs, nout, t);
    }
    finish(&fmu);
    if (fclose(out) != 0) die("cannot close %s", run->out_path);
}

/* Load the binary of the FMU extracted in `dir` (its absolute path into abs_dir). */
static void *load_binary(const char *dir, const ModelDescription *md, char *abs_dir, size_t size)
{
    char library[PATH_MAX + 256];
    if (!absolute_path(dir, abs_dir, size)) die("cannot resolve %s", dir);
    snprintf(library, sizeof library, "%s/binaries/%s/%s%s", abs_dir, md->fmi_version == 2 ? PLATFORM2 : PLATFORM3,
             md->model_identifier, LIBRARY_SUFFIX);
    void *lib = open_library(library);
    if (!lib) die("cannot load %s: %s", library, library_error());
    return lib;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: %s FMU_DIR OUT_CSV [--stop T] [--step H] [--start T0] [--clock ns|multiply] "
                        "[--in IN_CSV] [--set NAME=VALUE]... [--every N] [--refusals] [--threads N] "
                        "[--also FMU_DIR2]\n", argv[0]);
        return 1;
    }
    const char *fmu_dir = argv[1], *out_path = argv[2], *in_path = NULL, *also_dir = NULL;
    double stop = NAN, step = 1e-3, start = 0.0;
    const char *sets[MAX_SETS];
    int nsets = 0, refusals = 0, threads = 0, multiply = 0;
    long long every = 1;
    for (int i = 3; i < argc; i++) {
        if (strcmp(argv[i], "--refusals") == 0) {
            refusals = 1;
            continue;
        }
        if (i + 1 >= argc) die("option %s needs a value", argv[i]);
        if (strcmp(argv[i], "--stop") == 0) stop = strtod(argv[++i], NULL);
        else if (strcmp(argv[i], "--step") == 0) step = strtod(argv[++i], NULL);
        else if (strcmp(argv[i], "--start") == 0) start = strtod(argv[++i], NULL);
        else if (strcmp(argv[i], "--clock") == 0) {
            const char *clock = argv[++i];
            if (strcmp(clock, "multiply") == 0) multiply = 1;
            else if (strcmp(clock, "ns") != 0) die("--clock %s: allowed: ns, multiply", clock);
        } else if (strcmp(argv[i], "--in") == 0) in_path = argv[++i];
        else if (strcmp(argv[i], "--threads") == 0) threads = atoi(argv[++i]);
        else if (strcmp(argv[i], "--every") == 0) every = atoll(argv[++i]);
        else if (strcmp(argv[i], "--also") == 0) also_dir = argv[++i];
        else if (strcmp(argv[i], "--set") == 0) {
            if (nsets == MAX_SETS) die("too many --set");
            sets[nsets++] = argv[++i];
        } else die("unknown option %s", argv[i]);
    }
    if (every < 1) die("--every %lld: allowed range [1, %lld]", every, LLONG_MAX);
    if (threads < 0 || threads > MAX_THREADS) die("--threads %d: allowed range [1, %d]", threads, MAX_THREADS);

    ModelDescription *md = calloc(1, sizeof *md);
    if (!md) die("out of memory");
    parse_model_description(fmu_dir, md);
    if (isnan(stop)) stop = md->has_default_stop ? md->default_stop : 1.0;
    long long step_ns = llround(step * 1e9), nsteps;
    if (multiply) {
        if (!(step > 0.0 && isfinite(step))) die("--step %.17g: allowed range (0, inf) s", step);
        nsteps = llround((stop - start) / step);
    } else {
        if (!(step_ns > 0)) die("the step must be at least 1 ns");
        nsteps = llround((stop - start) * 1e9) / step_ns;
    }

    InputTable inputs = {0};
    if (in_path) read_inputs(in_path, md, &inputs);

    char abs_dir[PATH_MAX], also_abs[PATH_MAX];
    void *lib = load_binary(fmu_dir, md, abs_dir, sizeof abs_dir), *also_lib = NULL;
    ModelDescription *also_md = NULL;
    if (also_dir) {
        also_md = calloc(1, sizeof *also_md);
        if (!also_md) die("out of memory");
        parse_model_description(also_dir, also_md);
        also_lib = load_binary(also_dir, also_md, also_abs, sizeof also_abs);
    }

    Run runs[MAX_THREADS];
    for (int k = 0; k < (threads ? threads : 1); k++) {
        runs[k] = (Run){md, lib, abs_dir, "", sets, nsets, &inputs, start, stop, step, step_ns, nsteps, every, refusals,
                        multiply};
        snprintf(runs[k].out_path, sizeof runs[k].out_path, threads ? "%s.%d" : "%s", out_path, k + 1);
    }
    if (!threads) simulate(&runs[0]);
    else {
        Thread ids[MAX_THREADS];
        for (int k = 0; k < threads; k++)
            if (!start_thread(&ids[k], simulate, &runs[k])) die("cannot start thread %d", k + 1);
        for (int k = 0; k < threads; k++) join_thread(ids[k]);
    }
    if (also_dir) {
        Run also = {also_md, also_lib, also_abs, "", sets, nsets, &inputs, start, stop, step, step_ns, nsteps, every,
                    refusals, multiply};
        snprintf(also.out_path, sizeof also.out_path, "%s.also", out_path);
        simulate(&also);
        free(also_md);
    }
    free(inputs.time);
    free(inputs.values);
    free(md);
    /* The binary is not unloaded, and the process leaves without exit-time teardown (leave). */
    leave(0);
    return 0;
}
