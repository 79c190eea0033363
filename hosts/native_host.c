/*
 * native_host: a small FMI co-simulation host in plain C (no Python in it), for FMI 2.0 and 3.0.
 *
 * It loads an extracted FMU's binary with dlopen (binaries/linux64/<modelIdentifier>.so for FMI
 * 2.0, binaries/x86_64-linux/<modelIdentifier>.so for FMI 3.0; the version is the
 * modelDescription's fmiVersion), runs it over a fixed communication grid through the FMI C API
 * and writes every output to a CSV file in the FMI cross-check format ("time" first, quoted
 * names, %.17g so that every double is written exactly).
 *
 *   native_host FMU_DIR OUT_CSV [--stop T] [--step H] [--start T0] [--in IN_CSV]
 *                               [--set NAME=VALUE]...
 *
 * FMU_DIR  the FMU archive extracted (modelDescription.xml, binaries/, resources/).
 * --stop   stop time in s (default: DefaultExperiment stopTime, else 1).
 * --step   communication step in s (default: 1e-3). It is rounded to whole nanoseconds.
 * --start  start time in s (default 0).
 * --in     input CSV ("time" first, then one column per input, by name); values between two
 *          rows are linearly interpolated (FMI cross-check rules); a row at the exact grid time
 *          is used as it is.
 * --set    a start value for a parameter or input, by name (Real/Float64 or Integer/Int32).
 *
 * The communication grid is the one of OSP libcosim, which counts time in integer nanoseconds:
 * t_k = start + (k * step_ns) / 1e9 (the double nearest to k * step), and the step passed to
 * DoStep is t_{k+1} - t_k. The inputs of step k are those at t_k; they are set before DoStep.
 * Row k of the output is read after the step to t_k.
 *
 * Any call that returns a status other than OK is an error: the host says which call and which
 * status, and exits with status 1 (so does an FMI 3.0 step that asks to terminate). The FMU's
 * messages go to stderr. The binary is loaded with RTLD_NOW | RTLD_LOCAL into a process that
 * has no Python: the project's FMUs find one themselves (their loader). Exit status: 0 on
 * success, 1 on a usage or FMU error.
 */

#define _XOPEN_SOURCE 700

#include <dlfcn.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#define MAX_VARS 512
#define MAX_SETS 64
#define MAX_INPUT_COLS 64

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
    void *s = dlsym(lib, name);
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
    fmi2FreeInstanceTYPE *free2;
    fmi3SetFloat64TYPE *set_real3;
    fmi3SetInt32TYPE *set_integer3;
    fmi3GetFloat64TYPE *get_real3;
    fmi3GetInt32TYPE *get_integer3;
    fmi3EnterInitializationModeTYPE *enter_init3;
    fmi3ExitInitializationModeTYPE *exit_init3;
    fmi3DoStepTYPE *do_step3;
    fmi3TerminateTYPE *terminate3;
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
        fmu->free2 = (fmi2FreeInstanceTYPE *)symbol(lib, "fmi2FreeInstance");
        fmi2InstantiateTYPE *instantiate2 = (fmi2InstantiateTYPE *)symbol(lib, "fmi2Instantiate");
        static fmi2CallbackFunctions callbacks = {logger2, calloc, free, NULL, NULL};
        snprintf(resources, sizeof resources, "file://%s/resources", abs_dir);
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
        fmu->free3 = (fmi3FreeInstanceTYPE *)symbol(lib, "fmi3FreeInstance");
        fmi3InstantiateCoSimulationTYPE *instantiate3 =
            (fmi3InstantiateCoSimulationTYPE *)symbol(lib, "fmi3InstantiateCoSimulation");
        snprintf(resources, sizeof resources, "%s/resources/", abs_dir);
        fmu->c = instantiate3("native_host", md->guid, resources, fmi3False, fmi3True, fmi3False, fmi3False, NULL, 0,
                              NULL, logger3, NULL);
    }
    if (!fmu->c) die("fmi%dInstantiate%s failed", fmu->version, fmu->version == 3 ? "CoSimulation" : "");
}

static void set_real(const Fmu *fmu, unsigned int vr, double value, const char *what)
{
    if (fmu->version == 2) {
        fmi2ValueReference r = vr;
        check(fmu->set_real2(fmu->c, &r, 1, &value), what);
    } else {
        fmi3ValueReference r = vr;
        check(fmu->set_real3(fmu->c, &r, 1, &value, 1), what);
    }
}

static void set_integer(const Fmu *fmu, unsigned int vr, int value, const char *what)
{
    if (fmu->version == 2) {
        fmi2ValueReference r = vr;
        fmi2Integer v = value;
        check(fmu->set_integer2(fmu->c, &r, 1, &v), what);
    } else {
        fmi3ValueReference r = vr;
        fmi3Int32 v = value;
        check(fmu->set_integer3(fmu->c, &r, 1, &v, 1), what);
    }
}

static double get_real(const Fmu *fmu, unsigned int vr)
{
    double value;
    if (fmu->version == 2) {
        fmi2ValueReference r = vr;
        check(fmu->get_real2(fmu->c, &r, 1, &value), "fmi2GetReal");
    } else {
        fmi3ValueReference r = vr;
        check(fmu->get_real3(fmu->c, &r, 1, &value, 1), "fmi3GetFloat64");
    }
    return value;
}

static int get_integer(const Fmu *fmu, unsigned int vr)
{
    if (fmu->version == 2) {
        fmi2ValueReference r = vr;
        fmi2Integer value;
        check(fmu->get_integer2(fmu->c, &r, 1, &value), "fmi2GetInteger");
        return (int)value;
    }
    fmi3ValueReference r = vr;
    fmi3Int32 value;
    check(fmu->get_integer3(fmu->c, &r, 1, &value, 1), "fmi3GetInt32");
    return (int)value;
}

static void set_inputs(const Fmu *fmu, const InputTable *inputs, const ModelDescription *md, double t)
{
    for (int col = 0; col < inputs->ncols; col++)
        set_real(fmu, md->vars[inputs->var_index[col]].vr, input_at(inputs, col, t), "setting an input");
}

static void initialize(const Fmu *fmu, double start, double stop, const InputTable *inputs,
                       const ModelDescription *md)
{
    if (fmu->version == 2) {
        check(fmu->setup2(fmu->c, fmi2False, 0.0, start, fmi2True, stop), "fmi2SetupExperiment");
        set_inputs(fmu, inputs, md, start);
        check(fmu->enter_init2(fmu->c), "fmi2EnterInitializationMode");
        check(fmu->exit_init2(fmu->c), "fmi2ExitInitializationMode");
    } else {
        set_inputs(fmu, inputs, md, start);
        check(fmu->enter_init3(fmu->c, fmi3False, 0.0, start, fmi3True, stop), "fmi3EnterInitializationMode");
        check(fmu->exit_init3(fmu->c), "fmi3ExitInitializationMode");
    }
}

static void do_step(const Fmu *fmu, double t, double h)
{
    if (fmu->version == 2) {
        check(fmu->do_step2(fmu->c, t, h, fmi2True), "fmi2DoStep");
        return;
    }
    fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
    fmi3Float64 last = t;
    check(fmu->do_step3(fmu->c, t, h, fmi3True, &event, &terminate, &early, &last), "fmi3DoStep");
    if (terminate) die("fmi3DoStep at t = %.17g asked to terminate the simulation", t);
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

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: %s FMU_DIR OUT_CSV [--stop T] [--step H] [--start T0] [--in IN_CSV] "
                        "[--set NAME=VALUE]...\n", argv[0]);
        return 1;
    }
    const char *fmu_dir = argv[1], *out_path = argv[2], *in_path = NULL;
    double stop = NAN, step = 1e-3, start = 0.0;
    const char *sets[MAX_SETS];
    int nsets = 0;
    for (int i = 3; i < argc; i++) {
        if (i + 1 >= argc) die("option %s needs a value", argv[i]);
        if (strcmp(argv[i], "--stop") == 0) stop = strtod(argv[++i], NULL);
        else if (strcmp(argv[i], "--step") == 0) step = strtod(argv[++i], NULL);
        else if (strcmp(argv[i], "--start") == 0) start = strtod(argv[++i], NULL);
        else if (strcmp(argv[i], "--in") == 0) in_path = argv[++i];
        else if (strcmp(argv[i], "--set") == 0) {
            if (nsets == MAX_SETS) die("too many --set");
            sets[nsets++] = argv[++i];
        } else die("unknown option %s", argv[i]);
    }

    ModelDescription *md = calloc(1, sizeof *md);
    if (!md) die("out of memory");
    parse_model_description(fmu_dir, md);
    if (isnan(stop)) stop = md->has_default_stop ? md->default_stop : 1.0;
    long long step_ns = llround(step * 1e9);
    if (!(step_ns > 0)) die("the step must be at least 1 ns");
    long long nsteps = llround((stop - start) * 1e9) / step_ns;

    InputTable inputs = {0};
    if (in_path) read_inputs(in_path, md, &inputs);

    char abs_dir[PATH_MAX], library[PATH_MAX + 256];
    if (!realpath(fmu_dir, abs_dir)) die("cannot resolve %s", fmu_dir);
    snprintf(library, sizeof library, "%s/binaries/%s/%s.so", abs_dir,
             md->fmi_version == 2 ? "linux64" : "x86_64-linux", md->model_identifier);
    void *lib = dlopen(library, RTLD_NOW | RTLD_LOCAL);
    if (!lib) die("dlopen failed: %s", dlerror());

    Fmu fmu = {0};
    instantiate(&fmu, lib, md, abs_dir);

    for (int i = 0; i < nsets; i++) {
        char name[256], what[300];
        const char *eq = strchr(sets[i], '=');
        if (!eq || (size_t)(eq - sets[i]) >= sizeof name) die("--set %s: expected NAME=VALUE", sets[i]);
        memcpy(name, sets[i], (size_t)(eq - sets[i]));
        name[eq - sets[i]] = '\0';
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

    FILE *out = fopen(out_path, "w");
    if (!out) die("cannot write %s: %s", out_path, strerror(errno));
    fprintf(out, "\"time\"");
    for (int j = 0; j < nout; j++) fprintf(out, ",\"%s\"", md->vars[outputs[j]].name);
    fprintf(out, "\n");

    long long start_ns = llround(start * 1e9);
    double t = (double)start_ns / 1e9;
    initialize(&fmu, t, stop, &inputs, md);
    write_row(out, &fmu, md, outputs, nout, t);
    for (long long k = 0; k < nsteps; k++) {
        double t_next = (double)(start_ns + (k + 1) * step_ns) / 1e9;
        set_inputs(&fmu, &inputs, md, t);
        do_step(&fmu, t, t_next - t);
        t = t_next;
        write_row(out, &fmu, md, outputs, nout, t);
    }

    finish(&fmu);
    if (fclose(out) != 0) die("cannot close %s", out_path);
    free(inputs.time);
    free(inputs.values);
    free(md);
    /* The binary is not dlclose'd, and the process leaves without exit-time teardown (leave). */
    leave(0);
    return 0;
}
