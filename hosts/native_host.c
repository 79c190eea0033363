/*
 * native_host: a small FMI 2.0 co-simulation host in plain C (no Python in it).
 *
 * It loads an extracted FMU's binary (binaries/linux64/<modelIdentifier>.so) with dlopen, runs
 * it over a fixed communication grid through the FMI 2.0 C API and writes every output to a
 * CSV file in the FMI cross-check format ("time" first, quoted names, %.17g so that every
 * double is written exactly).
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
 * --set    a start value for a parameter or input, by name (Real or Integer).
 *
 * The communication grid is the one of OSP libcosim, which counts time in integer nanoseconds:
 * t_k = start + (k * step_ns) / 1e9 (the double nearest to k * step), and the step passed to
 * fmi2DoStep is t_{k+1} - t_k. The inputs of step k are those at t_k; they are set before
 * fmi2DoStep. Row k of the output is read after the step to t_k.
 *
 * The FMU's binary is loaded with RTLD_NOW | RTLD_LOCAL. A pythonfmu FMU needs libpython in the
 * process (its binary does not link it); hosts/run_native_host.sh is the launcher that provides
 * it. Exit status: 0 on success, 1 on a usage or FMU error.
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

#define MAX_VARS 512
#define MAX_SETS 64
#define MAX_INPUT_COLS 64

typedef struct {
    char name[128];
    unsigned int vr;
    char causality[16];
    char type[16]; /* "Real", "Integer", "Boolean", "String" */
} Variable;

typedef struct {
    Variable vars[MAX_VARS];
    int n;
    char guid[128];
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

static void parse_model_description(const char *fmu_dir, ModelDescription *md)
{
    char path[PATH_MAX];
    snprintf(path, sizeof path, "%s/modelDescription.xml", fmu_dir);
    char *xml = read_file(path);
    memset(md, 0, sizeof *md);

    const char *root = strstr(xml, "<fmiModelDescription");
    if (!root || !attribute(root, "guid", md->guid, sizeof md->guid))
        die("no guid in %s", path);
    const char *cs = strstr(xml, "<CoSimulation");
    if (!cs || !attribute(cs, "modelIdentifier", md->model_identifier, sizeof md->model_identifier))
        die("%s declares no CoSimulation modelIdentifier", path);
    const char *de = strstr(xml, "<DefaultExperiment");
    char buffer[64];
    if (de && attribute(de, "stopTime", buffer, sizeof buffer)) {
        md->default_stop = strtod(buffer, NULL);
        md->has_default_stop = 1;
    }

    for (const char *p = strstr(xml, "<ScalarVariable"); p; p = strstr(p + 1, "<ScalarVariable")) {
        if (md->n == MAX_VARS) die("more than %d variables", MAX_VARS);
        Variable *v = &md->vars[md->n];
        char vr[32];
        if (!attribute(p, "name", v->name, sizeof v->name) || !attribute(p, "valueReference", vr, sizeof vr))
            die("a ScalarVariable without name or valueReference");
        v->vr = (unsigned int)strtoul(vr, NULL, 10);
        if (!attribute(p, "causality", v->causality, sizeof v->causality))
            strcpy(v->causality, "local");
        const char *body = strchr(p, '>');
        const char *types[] = {"Real", "Integer", "Boolean", "String", "Enumeration"};
        v->type[0] = '\0';
        for (size_t i = 0; body && i < sizeof types / sizeof *types; i++) {
            char open[32];
            snprintf(open, sizeof open, "<%s", types[i]);
            const char *q = body + 1;
            while (*q == ' ' || *q == '\n' || *q == '\r' || *q == '\t') q++;
            if (strncmp(q, open, strlen(open)) == 0 && (q[strlen(open)] == ' ' || q[strlen(open)] == '/' ||
                                                        q[strlen(open)] == '>')) {
                strcpy(v->type, strcmp(types[i], "Enumeration") == 0 ? "Integer" : types[i]);
                break;
            }
        }
        if (!v->type[0]) die("variable %s has no type element", v->name);
        md->n++;
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
        if (strcmp(md->vars[index].type, "Real") != 0) die("%s: input %s is not Real", path, name);
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

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%s] %s (status %d): ", instance ? instance : "?", category ? category : "", (int)status);
    vfprintf(stderr, message, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}

static void *symbol(void *lib, const char *name)
{
    void *s = dlsym(lib, name);
    if (!s) die("the FMU binary has no %s", name);
    return s;
}

static void check(fmi2Status status, const char *what)
{
    if (status != fmi2OK && status != fmi2Warning) die("%s failed with status %d", what, (int)status);
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

    char abs_dir[PATH_MAX], library[PATH_MAX + 256], resources[PATH_MAX + 32];
    if (!realpath(fmu_dir, abs_dir)) die("cannot resolve %s", fmu_dir);
    snprintf(library, sizeof library, "%s/binaries/linux64/%s.so", abs_dir, md->model_identifier);
    snprintf(resources, sizeof resources, "file://%s/resources", abs_dir);

    void *lib = dlopen(library, RTLD_NOW | RTLD_LOCAL);
    if (!lib) die("dlopen failed: %s", dlerror());

    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)symbol(lib, "fmi2Instantiate");
    fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)symbol(lib, "fmi2FreeInstance");
    fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)symbol(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter_init =
        (fmi2EnterInitializationModeTYPE *)symbol(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exit_init =
        (fmi2ExitInitializationModeTYPE *)symbol(lib, "fmi2ExitInitializationMode");
    fmi2TerminateTYPE *terminate = (fmi2TerminateTYPE *)symbol(lib, "fmi2Terminate");
    fmi2SetRealTYPE *set_real = (fmi2SetRealTYPE *)symbol(lib, "fmi2SetReal");
    fmi2SetIntegerTYPE *set_integer = (fmi2SetIntegerTYPE *)symbol(lib, "fmi2SetInteger");
    fmi2GetRealTYPE *get_real = (fmi2GetRealTYPE *)symbol(lib, "fmi2GetReal");
    fmi2GetIntegerTYPE *get_integer = (fmi2GetIntegerTYPE *)symbol(lib, "fmi2GetInteger");
    fmi2DoStepTYPE *do_step = (fmi2DoStepTYPE *)symbol(lib, "fmi2DoStep");
    fmi2GetVersionTYPE *get_version = (fmi2GetVersionTYPE *)symbol(lib, "fmi2GetVersion");
    if (strcmp(get_version(), "2.0") != 0) die("the binary implements FMI %s, not 2.0", get_version());

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("native_host", fmi2CoSimulation, md->guid, resources, &callbacks,
                                  fmi2False, fmi2True);
    if (!c) die("fmi2Instantiate failed");

    for (int i = 0; i < nsets; i++) {
        char name[256];
        const char *eq = strchr(sets[i], '=');
        if (!eq || (size_t)(eq - sets[i]) >= sizeof name) die("--set %s: expected NAME=VALUE", sets[i]);
        memcpy(name, sets[i], (size_t)(eq - sets[i]));
        name[eq - sets[i]] = '\0';
        int index = find_variable(md, name);
        if (index < 0) die("--set: the FMU has no variable %s", name);
        fmi2ValueReference vr = md->vars[index].vr;
        if (strcmp(md->vars[index].type, "Real") == 0) {
            fmi2Real value = strtod(eq + 1, NULL);
            check(set_real(c, &vr, 1, &value), "fmi2SetReal");
        } else if (strcmp(md->vars[index].type, "Integer") == 0) {
            fmi2Integer value = (fmi2Integer)strtol(eq + 1, NULL, 10);
            check(set_integer(c, &vr, 1, &value), "fmi2SetInteger");
        } else die("--set %s: only Real and Integer variables", name);
    }

    /* the outputs, in model order */
    int outputs[MAX_VARS], nout = 0;
    for (int i = 0; i < md->n; i++)
        if (strcmp(md->vars[i].causality, "output") == 0) {
            if (strcmp(md->vars[i].type, "Real") != 0 && strcmp(md->vars[i].type, "Integer") != 0)
                die("output %s is neither Real nor Integer", md->vars[i].name);
            outputs[nout++] = i;
        }

    FILE *out = fopen(out_path, "w");
    if (!out) die("cannot write %s: %s", out_path, strerror(errno));
    fprintf(out, "\"time\"");
    for (int j = 0; j < nout; j++) fprintf(out, ",\"%s\"", md->vars[outputs[j]].name);
    fprintf(out, "\n");

    #define SET_INPUTS(t)                                                                  \
        for (int col = 0; col < inputs.ncols; col++) {                                     \
            fmi2ValueReference vr = md->vars[inputs.var_index[col]].vr;                    \
            fmi2Real value = input_at(&inputs, col, (t));                                  \
            check(set_real(c, &vr, 1, &value), "fmi2SetReal (input)");                      \
        }

    #define WRITE_ROW(t)                                                                   \
        do {                                                                               \
            fprintf(out, "%.17g", (t));                                                    \
            for (int j = 0; j < nout; j++) {                                               \
                const Variable *v = &md->vars[outputs[j]];                                 \
                fmi2ValueReference vr = v->vr;                                             \
                if (v->type[0] == 'R') {                                                   \
                    fmi2Real value;                                                        \
                    check(get_real(c, &vr, 1, &value), "fmi2GetReal");                     \
                    fprintf(out, ",%.17g", value);                                         \
                } else {                                                                   \
                    fmi2Integer value;                                                     \
                    check(get_integer(c, &vr, 1, &value), "fmi2GetInteger");               \
                    fprintf(out, ",%d", (int)value);                                       \
                }                                                                          \
            }                                                                              \
            fprintf(out, "\n");                                                            \
        } while (0)

    long long start_ns = llround(start * 1e9);
    double t = (double)start_ns / 1e9;
    check(setup(c, fmi2False, 0.0, t, fmi2True, stop), "fmi2SetupExperiment");
    SET_INPUTS(t);
    check(enter_init(c), "fmi2EnterInitializationMode");
    check(exit_init(c), "fmi2ExitInitializationMode");
    WRITE_ROW(t);

    for (long long k = 0; k < nsteps; k++) {
        double t_next = (double)(start_ns + (k + 1) * step_ns) / 1e9;
        SET_INPUTS(t);
        check(do_step(c, t, t_next - t, fmi2True), "fmi2DoStep");
        t = t_next;
        WRITE_ROW(t);
    }

    check(terminate(c), "fmi2Terminate");
    free_instance(c);
    if (fclose(out) != 0) die("cannot close %s", out_path);
    free(inputs.time);
    free(inputs.values);
    free(md);
    /* The binary is not dlclose'd, and the process leaves without exit-time teardown (leave). */
    leave(0);
    return 0;
}
