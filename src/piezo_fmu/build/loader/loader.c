/*
 * The binary of every FMU piezo-fmu builds (FMI 2.0 binaries/linux64 and binaries/win64, FMI 3.0
 * binaries/x86_64-linux and binaries/x86_64-windows), in front of pythonfmu's binary, which the
 * FMU keeps beside it as <modelIdentifier>.pythonfmu.so / .pythonfmu.dll. Compiled once per FMI
 * version and platform: -DFMI_VERSION=2 or 3, with the forwarders that generate.py writes from
 * the standard's headers (FORWARDERS names that file), and linked with the platform's layer
 * (platform.h: platform_posix.c, or platform_windows.c cross-compiled with mingw-w64). This file
 * is the logic, the same on both platforms.
 *
 * What it adds to pythonfmu's binary:
 *
 * 1. Python. pythonfmu's binary calls the Python C API but links no libpython, so it loads only
 *    into a process that has Python already. At the first instantiation the loader looks:
 *    - if the process has Python (Py_IsInitialized is found, as in fmpy, libcosimpy, ecospy),
 *      it changes nothing;
 *    - otherwise it takes $PIEZO_FMU_PYTHON (the path of an interpreter) alone, or else the
 *      platform's routes in order (Linux: python3 on PATH; Windows: py -3, python.exe on PATH,
 *      the PEP 514 registry entries of HKCU then HKLM). It runs each once (bounded by
 *      $PIEZO_FMU_PYTHON_TIMEOUT seconds, default 30) to learn its shared libpython or
 *      python3X.dll, sys.base_prefix and site-packages and that it imports numpy; the first
 *      usable one is loaded (libpython with RTLD_GLOBAL; python3X.dll, then python3.dll, by full
 *      path), PYTHONHOME is set if unset and the site-packages are added to the end of
 *      PYTHONPATH (a user's entries keep precedence, and a virtual environment's packages are
 *      found).
 *    A standalone FMU carries its own CPython in resources/python/<PLATFORM_RUNTIME>/ (a file
 *    library.txt there names its shared library, relative to that folder). In a process without
 *    Python the loader tries it first: it loads that library and sets PYTHONHOME to the folder
 *    (whatever it was: the runtime works with its own standard library only); if it cannot be
 *    loaded, the routes above follow. The normal FMUs have no such folder and skip this.
 *    When none is usable, instantiation returns NULL after a message through the host's logger
 *    that says what was tried and what to set. Nothing goes to stdout or stderr.
 * 2. Statuses. pythonfmu's binary returns only OK, Discard (a step that returns False) or Fatal
 *    (an exception). The slaves never raise: a call they refuse logs its reason with the error
 *    status and returns, and something unexpected is logged with the fatal status. The loader
 *    gives pythonfmu its own logger and returns, from every forwarded call, the worst of the
 *    status pythonfmu returned and the statuses of the messages logged during the call: a
 *    refused setter, ExitInitializationMode or step returns Error from that very call.
 * 3. Logging. pythonfmu 0.7.0 sends nothing to the logger, its Fatal messages included, unless
 *    debug logging is on (and pythonfmu3 filters Fatal messages by category). pythonfmu always
 *    runs with debug logging on; the loader passes on every message of status Warning or worse,
 *    and those of status OK when the host has turned debug logging on for their category.
 *
 * The instance the host holds is the loader's own (struct Instance) wrapping pythonfmu's; all
 * per-instance state is in it, so instances may live in different threads. What is process-wide
 * (the interpreter, pythonfmu's binary and its function table) is set up once (platform_once)
 * and not changed afterwards. An FMI 2.0 and an FMI 3.0 FMU in one process share one
 * interpreter: the second loader finds the first one's libpython in the process.
 */

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "platform.h"

#if FMI_VERSION == 2
#include "fmi2Functions.h"
typedef fmi2Status Status;
#define STATUS_OK fmi2OK
#define STATUS_ERROR fmi2Error
#define STATUS_FATAL fmi2Fatal
#elif FMI_VERSION == 3
#include "fmi3Functions.h"
typedef fmi3Status Status;
#define STATUS_OK fmi3OK
#define STATUS_ERROR fmi3Error
#define STATUS_FATAL fmi3Fatal
#else
#error "compile with -DFMI_VERSION=2 or -DFMI_VERSION=3"
#endif

#define DEFAULT_TIMEOUT_S 30.0
#define PROBLEM_SIZE 8192

typedef struct {
    void *real; /* pythonfmu's instance */
#if FMI_VERSION == 2
    fmi2CallbackFunctions host;  /* the host's callbacks */
    fmi2CallbackFunctions relay; /* what pythonfmu gets: the loader's logger, this instance */
    char *name;
#else
    fmi3InstanceEnvironment host_environment;
    fmi3LogMessageCallback host_log;
#endif
    int debug_logging;
    size_t ncategories;
    char **categories;
    Status logged; /* the worst status of the messages logged during the current call */
} Instance;

static Status finish(Instance *in, Status status);
static Status unsupported(Instance *in, const char *function);

#include FORWARDERS

static char problem[PROBLEM_SIZE]; /* why pythonfmu's binary could not be loaded; empty if it was */

/* -- messages to the host ---------------------------------------------------------------------- */

static void to_host(Instance *in, Status status, const char *category, const char *text)
{
#if FMI_VERSION == 2
    if (!in->host.logger) return;
    /* The FMI 2.0 message is a printf format: a '%' of the text is written "%%". */
    size_t percents = 0;
    for (const char *p = text; *p; p++) percents += *p == '%';
    char *escaped = percents ? malloc(strlen(text) + percents + 1) : NULL;
    if (escaped) {
        char *o = escaped;
        for (const char *p = text; *p; p++) {
            *o++ = *p;
            if (*p == '%') *o++ = '%';
        }
        *o = '\0';
    }
    in->host.logger(in->host.componentEnvironment, in->name, status, category,
                    escaped ? escaped : percents ? "(out of memory)" : text);
    free(escaped);
#else
    if (in->host_log) in->host_log(in->host_environment, status, category, text);
#endif
}

static int category_enabled(const Instance *in, const char *category)
{
    if (in->ncategories == 0) return 1;
    for (size_t i = 0; i < in->ncategories; i++)
        if (strcmp(in->categories[i], category) == 0) return 1;
    return 0;
}

/* A message of pythonfmu's binary: its status is kept for finish(), and it goes to the host. */
static void relay_message(Instance *in, Status status, const char *category, const char *message)
{
    if (!in || !message) return;
    category = category ? category : "";
    if (status > in->logged) in->logged = status;
    if (status != STATUS_OK || (in->debug_logging && category_enabled(in, category)))
        to_host(in, status, category, message);
}

#if FMI_VERSION == 2
/* pythonfmu passes the text itself as the format, with no arguments: it is used as it is. */
static void relay(fmi2ComponentEnvironment environment, fmi2String name, fmi2Status status,
                  fmi2String category, fmi2String message, ...)
{
    (void)name;
    relay_message(environment, status, category, message);
}
#else
static void relay(fmi3InstanceEnvironment environment, fmi3Status status, fmi3String category,
                  fmi3String message)
{
    relay_message(environment, status, category, message);
}
#endif

/* The status of a forwarded call: the worst of what pythonfmu returned and what was logged. */
static Status finish(Instance *in, Status status)
{
    Status logged = in->logged;
    in->logged = STATUS_OK;
    return logged > status ? logged : status;
}

static Status unsupported(Instance *in, const char *function)
{
    if (in) {
        char text[256];
        snprintf(text, sizeof text, "%s is not supported by this FMU", function);
        to_host(in, STATUS_ERROR, "logStatusError", text);
    }
    return STATUS_ERROR;
}

/* -- finding Python ---------------------------------------------------------------------------- */

static void set_problem(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(problem, sizeof problem, fmt, ap);
    va_end(ap);
}

/* What the interpreter says of itself: a marker line, then one value per line. The library is
 * the shared libpython on Linux, the python3X.dll the interpreter runs on on Windows. */
static const char QUERY[] =
    "import os, sys, sysconfig\n"
    "v = sysconfig.get_config_var\n"
    "if os.name == 'nt':\n"
    "    import ctypes\n"
    "    buffer = ctypes.create_unicode_buffer(32768)\n"
    "    ctypes.windll.kernel32.GetModuleFileNameW(ctypes.c_void_p(sys.dllhandle), buffer, 32768)\n"
    "    lib = buffer.value\n"
    "else:\n"
    "    names = [n for n in (v('INSTSONAME'), v('LDLIBRARY')) if n and '.so' in n]\n"
    "    dirs = [v('LIBDIR') or ''] + ([os.path.join('/usr/lib', v('MULTIARCH'))] if v('MULTIARCH') else [])\n"
    "    lib = next((p for p in (os.path.join(d, n) for d in dirs for n in names) if os.path.isfile(p)), '')\n"
    "try:\n"
    "    import numpy\n"
    "    numpy_error = ''\n"
    "except Exception as e:\n"
    "    numpy_error = repr(e).replace('\\n', ' ') or 'unknown error'\n"
    "packages = [p for p in sys.path if p.endswith(('site-packages', 'dist-packages')) and os.path.isdir(p)]\n"
    "print('PIEZO-FMU-PYTHON')\n"
    "print(lib)\n"
    "print(sys.base_prefix)\n"
    "print(os.pathsep.join(packages))\n"
    "print(numpy_error)\n";

/* Line `index` (0-based) of text after the marker, copied into out. */
static int fact_line(const char *text, int index, char *out, size_t size)
{
    for (int i = 0; i < index; i++) {
        text = strchr(text, '\n');
        if (!text) return 0;
        text++;
    }
    size_t n = strcspn(text, "\n");
    if (n >= size || text[n] != '\n') return 0;
    memcpy(out, text, n);
    out[n] = '\0';
    return 1;
}

static double query_timeout(void)
{
    char text[64];
    double timeout = platform_getenv("PIEZO_FMU_PYTHON_TIMEOUT", text, sizeof text) && *text ? strtod(text, NULL)
                                                                                             : DEFAULT_TIMEOUT_S;
    return timeout > 0 ? timeout : DEFAULT_TIMEOUT_S;
}

/* Run the interpreter of `route` once with QUERY. Returns 1 and the facts, or 0 with `why` filled. */
static int ask_python(const Route *route, PythonFacts *facts, char *why, size_t why_size)
{
    double timeout = query_timeout();
    char *output = NULL, failure[256] = "";
    int timed_out = 0, succeeded = 0;
    if (!platform_run(route, QUERY, timeout, &output, &timed_out, &succeeded, why, why_size)) return 0;
    int ok = 0;
    size_t length = strlen(output);
    const char *marker = strstr(output, "PIEZO-FMU-PYTHON\n");
    snprintf(failure, sizeof failure, "%.200s", why);
    if (timed_out) {
        snprintf(why, why_size, "it did not answer within %g s (PIEZO_FMU_PYTHON_TIMEOUT)", timeout);
    } else if (!marker || !succeeded) {
        char *end = output + length; /* its last line of output, if any, says why */
        while (end > output && (end[-1] == '\n' || end[-1] == ' ')) *--end = '\0';
        char *last = end;
        while (last > output && last[-1] != '\n') last--;
        snprintf(why, why_size, "it is not a working Python 3 (%s%s%.200s)", succeeded ? "it failed" : failure,
                 *last ? ": " : "", last);
    } else {
        marker += strlen("PIEZO-FMU-PYTHON\n");
        ok = fact_line(marker, 0, facts->library, sizeof facts->library)
             && fact_line(marker, 1, facts->home, sizeof facts->home)
             && fact_line(marker, 2, facts->packages, sizeof facts->packages)
             && fact_line(marker, 3, facts->numpy_error, sizeof facts->numpy_error);
        if (!ok) snprintf(why, why_size, "its answer could not be read");
    }
    free(output);
    return ok;
}

/* Add `entries` (path-separator-joined) to the end of PYTHONPATH, unless it ends with them. */
static int extend_pythonpath(const char *entries)
{
    if (!*entries) return 1;
    char old[4 * PATH_SIZE];
    if (!platform_getenv("PYTHONPATH", old, sizeof old) || !*old) return platform_setenv("PYTHONPATH", entries);
    size_t n = strlen(old), m = strlen(entries);
    if (n > m && strcmp(old + n - m, entries) == 0 && old[n - m - 1] == PLATFORM_PATH_SEPARATOR[0]) return 1;
    char *joined = malloc(n + m + 2);
    if (!joined) return 0;
    snprintf(joined, n + m + 2, "%s%s%s", old, PLATFORM_PATH_SEPARATOR, entries);
    int ok = platform_setenv("PYTHONPATH", joined);
    free(joined);
    return ok;
}

/* Load the interpreter of `facts` into the process with its environment: PYTHONHOME (replaced
 * when `own_home`, else set only if unset) and the site-packages at the end of PYTHONPATH. */
static int install_python(const PythonFacts *facts, int own_home, char *why, size_t why_size)
{
    char reason[2048], home[8];
    if (!platform_load_python(facts, reason, sizeof reason)) {
        snprintf(why, why_size, "%s", reason);
        return 0;
    }
    if ((own_home || !platform_getenv("PYTHONHOME", home, sizeof home)) && !platform_setenv("PYTHONHOME", facts->home)) {
        snprintf(why, why_size, "cannot set PYTHONHOME");
        return 0;
    }
    if (!extend_pythonpath(facts->packages)) {
        snprintf(why, why_size, "cannot set PYTHONPATH");
        return 0;
    }
    return 1;
}

/* The interpreter of one route in the process, or why not (0 and `why`). */
static int use_python(const Route *route, char *why, size_t why_size)
{
    PythonFacts facts;
    char reason[2048];
    if (!ask_python(route, &facts, reason, sizeof reason)) {
        snprintf(why, why_size, "%s", reason);
        return 0;
    }
    if (!facts.library[0]) {
        snprintf(why, why_size, "it has no shared libpython (it was built without --enable-shared)");
        return 0;
    }
    if (facts.numpy_error[0]) {
        snprintf(why, why_size, "it cannot import numpy (%s)", facts.numpy_error);
        return 0;
    }
    return install_python(&facts, 0, why, why_size);
}

/* The FMU's own runtime, if it carries one: 1 with its facts (the library that library.txt names,
 * the folder as home; numpy is in its own site-packages), else 0. */
static int own_runtime(PythonFacts *facts)
{
    char self[PATH_SIZE], name[PATH_SIZE] = "";
    if (!platform_self_path(self, sizeof self)) return 0;
    /* <FMU>/binaries/<platform>/<binary>: the FMU's folder is three separators up */
    for (int i = 0; i < 3; i++) {
        char *cut = strrchr(self, PLATFORM_DIR_SEPARATOR[0]);
        if (!cut) return 0;
        *cut = '\0';
    }
    int n = snprintf(facts->home, sizeof facts->home, "%s%sresources%spython%s%s", self, PLATFORM_DIR_SEPARATOR,
                     PLATFORM_DIR_SEPARATOR, PLATFORM_DIR_SEPARATOR, PLATFORM_RUNTIME);
    if (n < 0 || (size_t)n + sizeof "/library.txt" > sizeof facts->home) return 0;
    char listing[PATH_SIZE + 16];
    snprintf(listing, sizeof listing, "%s%slibrary.txt", facts->home, PLATFORM_DIR_SEPARATOR);
    FILE *file = fopen(listing, "r");
    if (!file) return 0;
    int read = fgets(name, sizeof name, file) != NULL;
    fclose(file);
    name[strcspn(name, "\r\n")] = '\0';
    if (!read || !*name) return 0;
    n = snprintf(facts->library, sizeof facts->library, "%s%s%s", facts->home, PLATFORM_DIR_SEPARATOR, name);
    facts->packages[0] = facts->numpy_error[0] = '\0';
    return n > 0 && (size_t)n < sizeof facts->library;
}

/* Put a Python into the process: the FMU's own runtime if it has one, else the first usable of
 * the platform's routes, or say why none was (returns 0 and sets `problem`). */
static int provide_python(void)
{
    if (platform_python_in_process()) return 1; /* the host has Python: use it */
    static Route routes[MAX_ROUTES];
    static PythonFacts own;
    char missing[PATH_SIZE], tried[PROBLEM_SIZE / 2] = "", why[2048];
    if (own_runtime(&own)) {
        if (install_python(&own, 1, why, sizeof why)) return 1;
        snprintf(tried, sizeof tried, "tried the FMU's own Python (%.1500s): %.2000s", own.home, why);
    }
    int count = platform_routes(routes, missing, sizeof missing);
    for (int i = 0; i < count; i++) {
        if (use_python(&routes[i], why, sizeof why)) return 1;
        size_t n = strlen(tried);
        snprintf(tried + n, sizeof tried - n, "%stried %s: %s", n ? "; " : "", routes[i].label, why);
    }
    set_problem("piezo-fmu: no Python for this FMU: %s%s%s. %s", missing, *missing && *tried ? "; " : "", tried,
                PLATFORM_ADVICE);
    return 0;
}

/* -- loading pythonfmu's binary ------------------------------------------------------------------ */

static void load(void)
{
    char self[PATH_SIZE], real[PATH_SIZE + 32], why[1024];
    if (!platform_self_path(self, sizeof self)) {
        set_problem("piezo-fmu: the FMU's binary cannot find its own path");
        return;
    }
    size_t n = strlen(self), suffix = strlen(PLATFORM_LIBRARY_SUFFIX);
    if (n <= suffix || strcmp(self + n - suffix, PLATFORM_LIBRARY_SUFFIX) != 0) {
        set_problem("piezo-fmu: unexpected name of the FMU's binary: %s", self);
        return;
    }
    snprintf(real, sizeof real, "%.*s%s", (int)(n - suffix), self, PLATFORM_REAL_SUFFIX);
    if (!provide_python()) return;
    void *library = platform_load(real, why, sizeof why);
    if (!library) {
        set_problem("piezo-fmu: cannot load pythonfmu's binary %s: %s", real, why);
        return;
    }
    for (int i = 0; i < F_COUNT; i++) real_functions[i] = platform_symbol(library, REAL_NAMES[i]);
}

/* -- instances -------------------------------------------------------------------------------- */

static char *copy_text(const char *text)
{
    char *copy = malloc(strlen(text) + 1);
    return copy ? strcpy(copy, text) : NULL;
}

static void free_instance(Instance *in)
{
    if (!in) return;
    for (size_t i = 0; i < in->ncategories; i++) free(in->categories[i]);
    free(in->categories);
#if FMI_VERSION == 2
    free(in->name);
#endif
    free(in);
}

/* pythonfmu's binary loaded (once per process); else the problem said through the host's logger */
static int ready(Instance *in, int instantiate)
{
    platform_once(load);
    if (!problem[0] && !real_functions[instantiate]) {
        set_problem("piezo-fmu: pythonfmu's binary has no %s", REAL_NAMES[instantiate]);
    }
    if (problem[0]) to_host(in, STATUS_ERROR, "logStatusError", problem);
    return !problem[0];
}

static Status set_debug_logging(Instance *in, int on, size_t n, const char *const categories[])
{
    if (!in) return STATUS_ERROR;
    char **copies = n ? calloc(n, sizeof *copies) : NULL;
    if (n && !copies) return STATUS_ERROR;
    for (size_t i = 0; i < n; i++) {
        copies[i] = copy_text(categories[i] ? categories[i] : "");
        if (!copies[i]) {
            while (i > 0) free(copies[--i]);
            free(copies);
            return STATUS_ERROR;
        }
    }
    for (size_t i = 0; i < in->ncategories; i++) free(in->categories[i]);
    free(in->categories);
    in->debug_logging = on;
    in->ncategories = n;
    in->categories = copies;
    return STATUS_OK;
}

/* FreeInstance: pythonfmu's instance (its free function is `index`), then ours. */
static void release(Instance *in, int index)
{
    if (!in) return;
    void (*free_real)(void *) = (void (*)(void *))real_functions[index];
    if (free_real && in->real) free_real(in->real);
    free_instance(in);
}

/* After pythonfmu's instantiate: NULL frees ours. */
static void *instantiated(Instance *in)
{
    finish(in, STATUS_OK);
    if (in->real) return in;
    free_instance(in);
    return NULL;
}

#if FMI_VERSION == 2

const char *fmi2GetTypesPlatform(void)
{
    return fmi2TypesPlatform;
}

const char *fmi2GetVersion(void)
{
    return fmi2Version;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    if (!functions || !fmuResourceLocation) return NULL;
    Instance *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->host = *functions;
    in->name = copy_text(instanceName ? instanceName : "");
    in->debug_logging = loggingOn;
    if (!in->name || !ready(in, F_fmi2Instantiate)) {
        free_instance(in);
        return NULL;
    }
    in->relay = (fmi2CallbackFunctions){relay, functions->allocateMemory, functions->freeMemory, NULL, in};
    in->real = ((fmi2InstantiateTYPE *)real_functions[F_fmi2Instantiate])(
        in->name, fmuType, fmuGUID ? fmuGUID : "", fmuResourceLocation, &in->relay, visible, fmi2True);
    return instantiated(in);
}

void fmi2FreeInstance(fmi2Component c)
{
    release(c, F_fmi2FreeInstance);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    return set_debug_logging(c, loggingOn, nCategories, categories);
}

#else

const char *fmi3GetVersion(void)
{
    return fmi3Version;
}

static Instance *new_instance(fmi3InstanceEnvironment environment, fmi3LogMessageCallback log,
                              fmi3Boolean loggingOn, fmi3String resourcePath, int instantiate)
{
    Instance *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->host_environment = environment;
    in->host_log = log;
    in->debug_logging = loggingOn;
    if (!resourcePath) to_host(in, fmi3Error, "logStatusError", "piezo-fmu: the FMU needs its resources folder");
    if (!resourcePath || !ready(in, instantiate)) {
        free_instance(in);
        return NULL;
    }
    return in;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    Instance *in = new_instance(instanceEnvironment, logMessage, loggingOn, resourcePath, F_fmi3InstantiateModelExchange);
    if (!in) return NULL;
    in->real = ((fmi3InstantiateModelExchangeTYPE *)real_functions[F_fmi3InstantiateModelExchange])(
        instanceName, instantiationToken, resourcePath, visible, fmi3True, in, relay);
    return instantiated(in);
}

/* pythonfmu3 calls no intermediate update; it gets none, so that no call can reach the host with
 * the loader's instance as its environment. */
fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)intermediateUpdate;
    Instance *in = new_instance(instanceEnvironment, logMessage, loggingOn, resourcePath,
                                    F_fmi3InstantiateCoSimulation);
    if (!in) return NULL;
    in->real = ((fmi3InstantiateCoSimulationTYPE *)real_functions[F_fmi3InstantiateCoSimulation])(
        instanceName, instantiationToken, resourcePath, visible, fmi3True, eventModeUsed, earlyReturnAllowed,
        requiredIntermediateVariables, nRequiredIntermediateVariables, in, relay, NULL);
    return instantiated(in);
}

/* pythonfmu3 throws out of this one (std::terminate in the host): answered here. */
fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "piezo-fmu: this FMU supports co-simulation and model exchange, not scheduled execution");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    release(instance, F_fmi3FreeInstance);
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    return set_debug_logging(instance, loggingOn, nCategories, categories);
}

#endif
