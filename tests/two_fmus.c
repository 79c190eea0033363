/*
 * two_fmus: an FMI 2.0 and an FMI 3.0 co-simulation FMU in one native process (no Python in it).
 *
 *   two_fmus FMU2_DIR ID2 GUID2 VR2 FMU3_DIR ID3 TOKEN3 VR3
 *
 * Instantiates the FMI 2.0 FMU (extracted in FMU2_DIR, model identifier ID2), then the FMI 3.0
 * one, initializes both and prints the Integer / Int32 output with value reference VR2 / VR3 of
 * each, one line each. tests/test_loader.py reads with it a counter that the slaves keep in
 * their interpreter, to show that the two FMUs share one; tests/test_windows.py builds it with
 * mingw-w64 and does the same under Wine (FMU_DIR then a Windows path). Exit status 1 on any
 * failure.
 */

#define _XOPEN_SOURCE 700

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
#define PLATFORM2 "win64"
#define PLATFORM3 "x86_64-windows"
#define SUFFIX ".dll"
#define URI_ROOT "file:///"
#define load(path) ((void *)LoadLibraryExA(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH))
#define dlsym(lib, name) ((void *)GetProcAddress((HMODULE)(lib), name))
#define dlerror() "LoadLibraryExA failed"
#else
#include <dlfcn.h>
#include <unistd.h>
#define PLATFORM2 "linux64"
#define PLATFORM3 "x86_64-linux"
#define SUFFIX ".so"
#define URI_ROOT "file://"
#define load(path) dlopen(path, RTLD_NOW | RTLD_LOCAL)
#endif

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

static void fail(const char *what)
{
    fprintf(stderr, "two_fmus: %s\n", what);
    fflush(NULL);
    _exit(1);
}

static void *open_binary(const char *dir, const char *platform, const char *id)
{
    char path[PATH_MAX];
    snprintf(path, sizeof path, "%s/binaries/%s/%s" SUFFIX, dir, platform, id);
    void *lib = load(path);
    if (!lib) fail(dlerror());
    return lib;
}

static void *symbol(void *lib, const char *name)
{
    void *s = dlsym(lib, name);
    if (!s) fail(name);
    return s;
}

static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                 fmi2String message, ...)
{
    (void)env, (void)name, (void)category;
    if (status != fmi2OK) fprintf(stderr, "FMI 2.0 FMU: %s\n", message);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env, (void)category;
    if (status != fmi3OK) fprintf(stderr, "FMI 3.0 FMU: %s\n", message);
}

int main(int argc, char **argv)
{
    if (argc != 9) fail("usage: two_fmus FMU2_DIR ID2 GUID2 VR2 FMU3_DIR ID3 TOKEN3 VR3");
    char uri[PATH_MAX + 32], resources[PATH_MAX + 32];

    void *lib2 = open_binary(argv[1], PLATFORM2, argv[2]);
    snprintf(uri, sizeof uri, URI_ROOT "%s/resources", argv[1]);
    for (char *p = uri; *p; p++)
        if (*p == '\\') *p = '/';
    static fmi2CallbackFunctions callbacks = {logger2, calloc, free, NULL, NULL};
    fmi2Component c2 = ((fmi2InstantiateTYPE *)symbol(lib2, "fmi2Instantiate"))(
        "fmi2", fmi2CoSimulation, argv[3], uri, &callbacks, fmi2False, fmi2False);
    if (!c2) fail("fmi2Instantiate");
    if (((fmi2EnterInitializationModeTYPE *)symbol(lib2, "fmi2EnterInitializationMode"))(c2) != fmi2OK ||
        ((fmi2ExitInitializationModeTYPE *)symbol(lib2, "fmi2ExitInitializationMode"))(c2) != fmi2OK)
        fail("FMI 2.0 initialization");

    void *lib3 = open_binary(argv[5], PLATFORM3, argv[6]);
    snprintf(resources, sizeof resources, "%s/resources/", argv[5]);
    fmi3Instance c3 = ((fmi3InstantiateCoSimulationTYPE *)symbol(lib3, "fmi3InstantiateCoSimulation"))(
        "fmi3", argv[7], resources, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, logger3, NULL);
    if (!c3) fail("fmi3InstantiateCoSimulation");
    if (((fmi3EnterInitializationModeTYPE *)symbol(lib3, "fmi3EnterInitializationMode"))(
            c3, fmi3False, 0.0, 0.0, fmi3False, 0.0) != fmi3OK ||
        ((fmi3ExitInitializationModeTYPE *)symbol(lib3, "fmi3ExitInitializationMode"))(c3) != fmi3OK)
        fail("FMI 3.0 initialization");

    fmi2ValueReference vr2 = (fmi2ValueReference)strtoul(argv[4], NULL, 10);
    fmi3ValueReference vr3 = (fmi3ValueReference)strtoul(argv[8], NULL, 10);
    fmi2Integer value2;
    fmi3Int32 value3;
    if (((fmi2GetIntegerTYPE *)symbol(lib2, "fmi2GetInteger"))(c2, &vr2, 1, &value2) != fmi2OK) fail("fmi2GetInteger");
    if (((fmi3GetInt32TYPE *)symbol(lib3, "fmi3GetInt32"))(c3, &vr3, 1, &value3, 1) != fmi3OK) fail("fmi3GetInt32");
    printf("%d\n%d\n", (int)value2, (int)value3);

    ((fmi2FreeInstanceTYPE *)symbol(lib2, "fmi2FreeInstance"))(c2);
    ((fmi3FreeInstanceTYPE *)symbol(lib3, "fmi3FreeInstance"))(c3);
    fflush(NULL);
    _exit(0); /* as native_host: no exit-time teardown of the embedded interpreter */
}
