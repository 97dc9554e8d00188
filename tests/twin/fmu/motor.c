/* A DC motor as an FMI 2.0 FMU (Model Exchange and Co-Simulation), built at test time by
 * tests/twin/fmu/build.py with the FMI headers fmpy ships:
 *
 *     i' = (V - R*i - Ke*w)/L,   w' = (Kt*i - b*w)/J,   outputs i and w
 *
 * the physics of the motor benchmark family (dtwin/gapbench/family_assets.py), written as the
 * one expression module of tests/twin/fmu/twins.py with the same operations in the same order.
 * Co-Simulation steps with RK4 (COSIM_SUBSTEPS per communication step), the input linear over
 * the step when its derivative is set (canInterpolateInputs). An inductance L <= 0 or an
 * inertia J <= 0 fails to initialise with a logged error. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

enum { VR_V, VR_I, VR_DER_I, VR_W, VR_DER_W, VR_R, VR_L, VR_KE, VR_KT, VR_J, VR_B, VR_TAU_M,
       N_VARS };
#define COSIM_SUBSTEPS 8
#define GUID "{dtwin-motor-1}"

typedef struct {
    fmi2Real r[N_VARS];
    fmi2Real time;
    fmi2Real du; /* input derivative over a communication step */
    fmi2Type type;
    fmi2CallbackFunctions cb;
    char name[64];
} Model;

static void set_start(Model *m) {
    memset(m->r, 0, sizeof(m->r));
    m->r[VR_R] = 2.0;
    m->r[VR_L] = 0.01;
    m->r[VR_KE] = 0.1;
    m->r[VR_KT] = 0.1;
    m->r[VR_J] = 5e-4;
    m->r[VR_B] = 7.5e-4;
    m->time = 0.0;
    m->du = 0.0;
}

static void derive(Model *m, fmi2Real V, const fmi2Real *s, fmi2Real *d) {
    const fmi2Real *r = m->r;
    d[0] = (V - r[VR_R] * s[0] - r[VR_KE] * s[1]) / r[VR_L];
    d[1] = (r[VR_KT] * s[0] - r[VR_B] * s[1]) / r[VR_J];
}

static void calculate(Model *m) {
    fmi2Real s[2] = {m->r[VR_I], m->r[VR_W]}, d[2];
    derive(m, m->r[VR_V], s, d);
    m->r[VR_DER_I] = d[0];
    m->r[VR_DER_W] = d[1];
    m->r[VR_TAU_M] = m->r[VR_J] * m->r[VR_R] / (m->r[VR_KT] * m->r[VR_KE]);
}

static fmi2Status refuse(Model *m, const char *what, fmi2Real value) {
    m->cb.logger(m->cb.componentEnvironment, m->name, fmi2Error, "logStatusError",
                 "motor: %s must be > 0 (got %g)", what, value);
    return fmi2Error;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String resources, const fmi2CallbackFunctions *cb,
                              fmi2Boolean visible, fmi2Boolean logging) {
    (void)resources; (void)visible; (void)logging;
    if (strcmp(guid, GUID) != 0) return NULL;
    Model *m = calloc(1, sizeof(Model));
    if (!m) return NULL;
    m->type = type;
    m->cb = *cb;
    strncpy(m->name, name, sizeof(m->name) - 1);
    set_start(m);
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat; return fmi2OK;
}
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol,
                               fmi2Real start, fmi2Boolean stop_defined, fmi2Real stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    ((Model *)c)->time = start;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Model *m = c;
    if (!(m->r[VR_L] > 0)) return refuse(m, "inductance L", m->r[VR_L]);
    if (!(m->r[VR_J] > 0)) return refuse(m, "inertia J", m->r[VR_J]);
    calculate(m);
    return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { set_start(c); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Model *m = c;
    calculate(m);
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS) return fmi2Error;
        v[i] = m->r[vr[i]];
    }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real v[]) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARS) return fmi2Error;
        m->r[vr[i]] = v[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; (void)n; return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; (void)b; (void)n; (void)s; return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz,
                                        const fmi2Real dz[], fmi2Real dv[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dz; (void)dv; return fmi2Error;
}

/* Model Exchange */
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    (void)c;
    memset(info, 0, sizeof(*info));
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean no_prior,
                                       fmi2Boolean *enter, fmi2Boolean *terminate) {
    (void)c; (void)no_prior;
    *enter = fmi2False;
    *terminate = fmi2False;
    return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((Model *)c)->time = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) {
    Model *m = c;
    if (n != 2) return fmi2Error;
    m->r[VR_I] = x[0];
    m->r[VR_W] = x[1];
    return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) {
    Model *m = c;
    if (n != 2) return fmi2Error;
    fmi2Real s[2] = {m->r[VR_I], m->r[VR_W]};
    derive(m, m->r[VR_V], s, d);
    return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t n) {
    (void)c; (void)z; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    Model *m = c;
    if (n != 2) return fmi2Error;
    x[0] = m->r[VR_I];
    x[1] = m->r[VR_W];
    return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    (void)c;
    for (size_t i = 0; i < n; i++) x[i] = 1.0;
    return fmi2OK;
}

/* Co-Simulation */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_V || order[i] != 1) return fmi2Error;
        m->du = v[i];
    }
    return fmi2OK;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) {
    (void)c; (void)vr; (void)order; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    Model *m = c;
    (void)no_prior;
    fmi2Real u0 = m->r[VR_V], s[2] = {m->r[VR_I], m->r[VR_W]}, trial[2];
    fmi2Real k1[2], k2[2], k3[2], k4[2], step = h / COSIM_SUBSTEPS;
    for (int j = 0; j < COSIM_SUBSTEPS; j++) {
        fmi2Real a = j * step, u_a = u0 + m->du * a, u_m = u0 + m->du * (a + 0.5 * step);
        fmi2Real u_b = u0 + m->du * (a + step);
        derive(m, u_a, s, k1);
        for (int i = 0; i < 2; i++) trial[i] = s[i] + 0.5 * step * k1[i];
        derive(m, u_m, trial, k2);
        for (int i = 0; i < 2; i++) trial[i] = s[i] + 0.5 * step * k2[i];
        derive(m, u_m, trial, k3);
        for (int i = 0; i < 2; i++) trial[i] = s[i] + step * k3[i];
        derive(m, u_b, trial, k4);
        for (int i = 0; i < 2; i++) s[i] += step / 6.0 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
    }
    m->r[VR_I] = s[0];
    m->r[VR_W] = s[1];
    m->r[VR_V] = u0 + m->du * h;
    m->du = 0.0;
    m->time = t + h;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)c; (void)s; (void)v; return fmi2Discard;
}
