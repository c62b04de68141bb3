// SimTwo's RobotFactoryPro2022 AGV (AGV.xml) in ODE 0.16 as SimTwo sets it up (Viewer.pas): a probe of why the
// robot turns more on the spot than its encoders say (docs/simtwo.md, "Odometry on SimTwo: the turns on the spot").
// The same bodies, masses, geoms, hinges (anchored on the robot's centre line, AGV.xml 123/132), the board, the
// contact parameters of nearCallback (Viewer.pas 416-436: Approx1, soft CFM 1e-5, mu 0.95, bounce 0.6), QuickStep
// with 30 iterations (config_Params.ini), ERP 0.4, CFM 1e-5, SimTwo's DC motor and CalcPID with control.pas's gains
// (0 V for 9 ms after each 40 ms script call). Prints, per segment, the truth's turn against the encoders'.
//   gcc -O2 simtwo/test/ode_agv.c -o /tmp/ode_agv -lode -lm && /tmp/ode_agv [spin=0.5] [anchor=0.0675]
//   [wheel=sphere] [maxc=1] [step=exact] [iters=N] [approx=0] [board=0] [pad=0]   (DIAG=1: rim loads, camber)
// Debian's libode-dev 0.16.2 (double precision, as SimTwo's Linux build).
#include <ode/ode.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
typedef struct { int surf; double mu, cfm; } Surf;
static dWorldID world; static dSpaceID space; static dJointGroupID cg;
static Surf pad_surf = {1, 0.1, 0.1};
static int use_approx1 = 1, quick = 1, iters = 30, maxc = 7;
static double MU = 0.95;
static dJointFeedback fb[64]; static double fby[64]; static dBodyID fbw[64]; static int nfb=0; static dBodyID WB[2];
static void near(void *d, dGeomID o1, dGeomID o2) {
  dBodyID b1 = dGeomGetBody(o1), b2 = dGeomGetBody(o2);
  if (b1 && b2 && dAreConnectedExcluding(b1, b2, dJointTypeContact)) return;
  dContact c[7]; memset(c, 0, sizeof c);
  int n = dCollide(o1, o2, maxc, &c[0].geom, sizeof(dContact));
  double mu = MU, cfm = 1e-5;
  Surf *s1 = dGeomGetData(o1), *s2 = dGeomGetData(o2);
  if (s1 && s1->surf) { mu = s1->mu; cfm = s1->cfm; }
  if (s2 && s2->surf) { mu = sqrt(mu * s2->mu); cfm = fmax(cfm, s2->cfm); }
  for (int i = 0; i < n; i++) {
    c[i].surface.mode = dContactBounce | dContactSoftCFM | (use_approx1 ? dContactApprox1 : 0);
    c[i].surface.mu = mu; c[i].surface.mu2 = mu; c[i].surface.soft_cfm = cfm;
    c[i].surface.bounce = 0.6; c[i].surface.bounce_vel = 0.001;
    dJointID j = dJointCreateContact(world, cg, &c[i]);
    dJointAttach(j, dGeomGetBody(c[i].geom.g1), dGeomGetBody(c[i].geom.g2));
    for (int s = 0; s < 2; s++) if ((b1 == WB[s] || b2 == WB[s]) && nfb < 64) {
      const dReal *wp = dBodyGetPosition(WB[s]);
      dJointSetFeedback(j, &fb[nfb]); fby[nfb] = (c[i].geom.pos[1] - wp[1]) * (s == 0 ? 1 : -1); fbw[nfb] = WB[s]; nfb++; }
  }
}
typedef struct { double I, S, V, wref; dJointID j; } Motor;
static const double R = 6.1, L = 3.4e-3, K = 0.2585, Vmax = 8.2, Imax = 3, Bv = 0.0012, Fc = 0.0169;
static double kp = 0.1, ki = 100, kf = 0.42;
static void motor_step(Motor *m, double dt) {
  double w = dJointGetHingeAngleRate(m->j);
  double V = fmax(-Vmax, fmin(Vmax, m->V));
  double a = exp(-dt * R / L), In = a * m->I + (1 - a) * (V - K * w) / R;
  double dI = fmax(-0.5, fmin(0.5, In - m->I)); m->I = fmax(-Imax, fmin(Imax, m->I + dI));
  double tau = K * m->I - Bv * w - (w > 0 ? Fc : (w < 0 ? -Fc : 0));
  dJointAddHingeTorque(m->j, tau);
}
static void pid(Motor *m) {
  double w = dJointGetHingeAngleRate(m->j), e = m->wref - w;
  m->S += e * 0.001; double v = kp * e + ki * m->S + kf * m->wref;
  if (fabs(v) >= Vmax) { m->S -= e * 0.001; v = v > 0 ? Vmax : -Vmax; }
  m->V = v;
}
int main(int argc, char **argv) {
  // options: wheel=cyl|sphere  step=quick|exact  iters=N  maxc=N  approx=0|1 mu=X  board=1|0  pad=1|0 track=X
  const char *wheel = "cyl"; int board = 1, pad = 1; double spin = 1.5, track_nom = 0.135, anchor_y = 0; double cfm_w = 1e-5, erp_w = 0.4;
  for (int i = 1; i < argc; i++) {
    char k[64]; char v[64]; if (sscanf(argv[i], "%63[^=]=%63s", k, v) != 2) continue;
    if (!strcmp(k, "wheel")) wheel = strdup(v); else if (!strcmp(k, "step")) quick = !strcmp(v, "quick");
    else if (!strcmp(k, "iters")) iters = atoi(v); else if (!strcmp(k, "maxc")) maxc = atoi(v);
    else if (!strcmp(k, "approx")) use_approx1 = atoi(v); else if (!strcmp(k, "mu")) MU = atof(v);
    else if (!strcmp(k, "board")) board = atoi(v); else if (!strcmp(k, "pad")) pad = atoi(v);
    else if (!strcmp(k, "spin")) spin = atof(v); else if (!strcmp(k, "anchor")) anchor_y = atof(v);
    else if (!strcmp(k, "cfm")) cfm_w = atof(v); else if (!strcmp(k, "erp")) erp_w = atof(v);
  }
  dInitODE2(0);
  world = dWorldCreate(); space = dSimpleSpaceCreate(0); cg = dJointGroupCreate(0);
  dWorldSetGravity(world, 0, 0, -9.81); dWorldSetCFM(world, cfm_w); dWorldSetERP(world, erp_w);
  dWorldSetQuickStepNumIterations(world, iters);
  dCreatePlane(space, 0, 0, 1, 0);
  if (board) { dGeomID f = dCreateBox(space, 1.68, 1.18, 0.001); dGeomSetPosition(f, 0, 0, 0.0005); }
  double z0 = board ? 0.001 : 0.0;
  // base plate 0.14 x 0.105 x 0.003, 1 kg, centre z 0.0165; slide pad shell: sphere r 0.008, 0.02 kg at (-0.055, 0, -0.008)
  dBodyID base = dBodyCreate(world); dMass m, m2;
  dMassSetBoxTotal(&m, 1.0, 0.14, 0.105, 0.003);
  dGeomID bg = dCreateBox(space, 0.14, 0.105, 0.003); dGeomSetBody(bg, base);
  if (pad) {
    dMassSetSphereTotal(&m2, 0.02, 0.008); dMassTranslate(&m2, -0.055, 0, -0.008); dMassAdd(&m, &m2);
  }
  double cx = m.c[0], cy = m.c[1], cz = m.c[2];
  dMassTranslate(&m, -cx, -cy, -cz);  // ODE: the body's origin at its centre of mass
  dBodySetMass(base, &m);
  dBodySetPosition(base, cx, cy, z0 + 0.0165 + cz);
  dGeomSetOffsetPosition(bg, -cx, -cy, -cz);
  if (pad) { dGeomID pg = dCreateSphere(space, 0.008); dGeomSetBody(pg, base); dGeomSetData(pg, &pad_surf);
             dGeomSetOffsetPosition(pg, -0.055 - cx, -cy, -0.008 - cz); }
  Motor mot[2]; memset(mot, 0, sizeof mot); dBodyID wb[2];
  for (int s = 0; s < 2; s++) {  // 0 left (+y), 1 right
    double y = (s == 0 ? 1 : -1) * 0.0675;
    wb[s] = dBodyCreate(world); WB[s] = wb[s];
    dMassSetCylinderTotal(&m, 0.05, 3, 0.0325, 0.006); dBodySetMass(wb[s], &m);
    dBodySetPosition(wb[s], 0, y, z0 + 0.0325);
    dMatrix3 Rm; dRFromAxisAndAngle(Rm, 1, 0, 0, M_PI / 2); dBodySetRotation(wb[s], Rm);
    dGeomID g = !strcmp(wheel, "sphere") ? dCreateSphere(space, 0.0325) : dCreateCylinder(space, 0.0325, 0.006);
    dGeomSetBody(g, wb[s]);
    dJointID j = dJointCreateHinge(world, 0); dJointAttach(j, wb[s], base);
    dJointSetHingeAnchor(j, 0, anchor_y * y / 0.0675, z0 + 0.0325); dJointSetHingeAxis(j, 0, 1, 0);
    dJointSetHingeParam(j, dParamStopCFM, 1e-5);
    mot[s].j = j;
  }
  // drive: settle 2 s, spin pi/spin s, straight 0.2 m/s 1.5 s, stop 1.5; then straight 3 s, stop
  struct { double t, v, w; const char *n; } plan[] = {{2, 0, 0, "settle"}, {M_PI / fabs(spin), 0, spin, "spin"},
    {1.5, 0.2, 0, "after_spin"}, {1.0, 0, 0, "stop"}, {3.0, 0.2, 0, "straight"}, {1.0, 0, 0, "stop2"}};
  int np = 6, seg = 0; double tseg = plan[0].t, t = 0; long step = 0;
  double yaw = 0, lastyaw = 0, encL = 0, encR = 0, lastL = 0, lastR = 0;
  double mk_yaw = 0, mk_enc = 0, mk_x = 0, mk_y = 0, mk_encd = 0;
  double r = 0.0325;
  for (;;) {
    if (step % 40 == 0) {  // script call: references, volts zeroed (Viewer.pas 5255-5260)
      if (t >= tseg - 1e-9) {
        const dReal *p = dBodyGetPosition(base);
        double eyaw = r * (encR - encL) / track_nom, ed = r * (encR + encL) / 2;
        printf("%-10s truth_turn %8.3f deg enc_turn %8.3f deg ratio %.4f | truth_d %.4f enc_d %.4f\n", plan[seg].n,
               (yaw - mk_yaw) * 180 / M_PI, (eyaw - mk_enc) * 180 / M_PI,
               fabs(eyaw - mk_enc) > 1e-3 ? (yaw - mk_yaw) / (eyaw - mk_enc) : 0,
               hypot(p[0] - mk_x, p[1] - mk_y), ed - mk_encd);
        mk_yaw = yaw; mk_enc = eyaw; mk_x = p[0]; mk_y = p[1]; mk_encd = ed;
        if (++seg >= np) break;
        tseg += plan[seg].t;
      }
      double v = plan[seg].v, w = plan[seg].w;
      mot[0].wref = (v - w * track_nom / 2) / r; mot[1].wref = (v + w * track_nom / 2) / r;
      mot[0].V = mot[1].V = 0;
    }
    if (step % 10 == 9) { pid(&mot[0]); pid(&mot[1]); }
    motor_step(&mot[0], 0.001); motor_step(&mot[1], 0.001);
    nfb = 0; dSpaceCollide(space, 0, near);
    if (quick) dWorldQuickStep(world, 0.001); else dWorldStep(world, 0.001);
    if (getenv("DIAG") && step % 200 == 0) { double fi=0, fo=0, yi=0, yo=0; int ni=0, no=0; for (int k=0;k<nfb;k++) { double fz = fbw[k]==WB[0] ? fb[k].f1[2] : -fb[k].f2[2]; if (fb[k].f1[2]!=0 || 1) { if (fby[k] < 0) { fi += fb[k].f1[2]; yi += fby[k]; ni++; } else { fo += fb[k].f1[2]; yo += fby[k]; no++; } } }
      dVector3 ax; dJointGetHingeAxis(mot[0].j, ax);
      printf("t %.2f seg %s contacts %d: inner (outward offset %.4f) Fz %.3f N, outer (%.4f) Fz %.3f N; left axle z-tilt %.5f rad\n", t, plan[seg].n, nfb, ni?yi/ni:0, fi, no?yo/no:0, fo, ax[2]); }
    dJointGroupEmpty(cg);
    step++; t = step * 0.001;
    const dReal *q = dBodyGetRotation(base);
    double th = atan2(q[4], q[0]);
    double d = th - lastyaw; while (d > M_PI) d -= 2 * M_PI; while (d < -M_PI) d += 2 * M_PI; yaw += d; lastyaw = th;
    // encoders: the hinge angles (left wheel is mot[0] but its geometric +y is left)
    double aL = dJointGetHingeAngle(mot[0].j), aR = dJointGetHingeAngle(mot[1].j);
    double dl = aL - lastL, dr = aR - lastR;
    while (dl > M_PI) dl -= 2 * M_PI; while (dl < -M_PI) dl += 2 * M_PI;
    while (dr > M_PI) dr -= 2 * M_PI; while (dr < -M_PI) dr += 2 * M_PI;
    encL += dl; encR += dr; lastL = aL; lastR = aR;
  }
  const dReal *p = dBodyGetPosition(base);
  printf("final z %.5f\n", p[2]);
  return 0;
}
