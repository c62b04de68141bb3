// robotatfactory: abi_check.pas - a SimTwo scene script (PascalScript, as SimTwo compiles it) that calls
// every native function SimTwo registers for scene scripts that takes or returns a record by value or const
// (var/out are pointers on both sides and are not checked), with known inputs, and checks the results.
// Run it as the control script of a fresh copy of the RobotFactoryPro2022 scene (robot 'AGV').
// Output, one line per check:  ABI <FunctionName> ok  |  ABI <FunctionName> FAIL <got> <expected>
// and finally:                 ABI done <n_ok> <n_fail>
// Extra lines 'ABI <name> ...' for arcsin, arccos, tan, Power, Log10, LogN, RandG (Extended, not records)
// and FloatAsInteger/IntegerAsFloat (Single) check the other non-trivial float types of the script API.
//
// Every check runs in its own try/except: a native call that sees its arguments shifted may raise
// (list index out of bounds, access violation); that is reported as FAIL exception:<message>.
// Checks that change the scene (motor pars, solid pose, trajectory points) come after the read-only ones.
// The checks run at cycle ABI_START; GetCameraPixel's waits for a camera image, then 'ABI done' is printed.
// Writes abi_check_matrix.txt (Msave/Mload) in SimTwo's working directory and cells 30..34 x 10..11 of the sheet.
//
// Record-taking/returning functions NOT checked here, and why:
//   GetPaintTargetExtents (TExtents result, 48 bytes), CalculateSprayThicknessHistogram (THistogram
//     result), GetPaintTargetTriangles (TTriangles = dynamic array of TFace result), SetResultTrianglesColor
//     (open array of TPoint3D): they need a paint target thing (a spray-painting scene); RobotFactoryPro2022
//     has none. TExtents is returned like TPoint3D/TAxisState (more than 16 bytes: hidden result pointer,
//     which PascalScript passes first), THistogram like Matrix (managed fields: hidden result pointer), and
//     an open array is a pointer and a high bound on both sides.
//   GetGlobalSensorValues (Matrix result): the scene has no global sensors (same code path as
//     GetSensorValues, which is checked).
//   TUDPBuffer (NetPut*/NetGet*, ClearUDPBuffer, NetBufferSeek, NetStringBuffer) and MInit, MSetSize, Msetv,
//     MUsetv, ArrayToMatrix take their record as var: a pointer on both sides (used here, not checked).
//   GetJointWayPoint (TAxisPoint result): only when the scene folder holds abi_check_waypoints.xml (see
//     CheckAxesReadOnly); a script cannot write that file itself. Same type and path as GetAxisTrajPoint.
//   GetCameraPixel (TRGBAColor result) is checked only weakly: no exception and components in 0..255 once the
//     camera renders (open the Cameras window: Ctrl+A in the viewer, e.g. xdotool); see CameraCheck.
//   TSpringDef, TGLPixel32: no registered function takes or returns them (GetAxisSpring is not registered;
//     GetCameraPixel returns TRGBAColor).

const
  ABI_PI = 3.14159265358979;
  ABI_WPFILE = 'abi_check_waypoints.xml';
  ABI_MFILE = 'abi_check_matrix.txt';
  ABI_START = 25;         // cycles before the checks run (the scene settles)
  ABI_CAMERA_WAIT = 500;  // cycles more GetCameraPixel's check waits for a camera image (20 s at 40 ms)

var
  nOk, nFail: integer;
  AbiDone, AbiCamera: boolean;
  AbiCycle: integer;
  RAGV, iBase, iLeftAxis: integer;

// ---------------------------------------------------------------------------------------------- helpers

function F2S(x: double): string;
begin
  result := Format('%.6g', [x]);
end;

function P2S(x, y, z: double): string;
begin
  result := '(' + F2S(x) + ',' + F2S(y) + ',' + F2S(z) + ')';
end;

function M2S(M: Matrix): string;
var r, c: integer;
begin
  result := '[' + IntToStr(MNumRows(M)) + 'x' + IntToStr(MNumCols(M));
  if MNumRows(M) * MNumCols(M) <= 16 then begin
    result := result + ':';
    for r := 0 to MNumRows(M) - 1 do begin
      for c := 0 to MNumCols(M) - 1 do begin
        result := result + ' ' + F2S(Mgetv(M, r, c));
      end;
      if r < MNumRows(M) - 1 then result := result + ';';
    end;
  end;
  result := result + ']';
end;

function C2S(c: TRGBAColor): string;
begin
  result := '(' + IntToStr(c.Red) + ',' + IntToStr(c.Green) + ',' + IntToStr(c.Blue) + ',' + IntToStr(c.alpha) + ')';
end;

procedure Report(name: string; good: boolean; got, expected: string);
begin
  if good then begin
    WriteLn('ABI ' + name + ' ok');
    nOk := nOk + 1;
  end else begin
    WriteLn('ABI ' + name + ' FAIL ' + got + ' ' + expected);
    nFail := nFail + 1;
  end;
end;

function NoSpaces(s: string): string;
var i: integer;
begin
  result := s;
  for i := 1 to Length(result) do begin
    if result[i] = ' ' then result[i] := '_';
  end;
end;

procedure ReportException(name: string);
begin
  Report(name, false, 'exception:' + NoSpaces(ExceptionToString(ExceptionType, ExceptionParam)), '-');
end;

function Near(a, b, tol: double): boolean;
begin
  result := abs(a - b) <= tol;
end;

procedure CheckF(name: string; got, expected, tol: double);
begin
  Report(name, Near(got, expected, tol), F2S(got), F2S(expected));
end;

procedure CheckP(name: string; gx, gy, gz, ex, ey, ez, tol: double);
begin
  Report(name, Near(gx, ex, tol) and Near(gy, ey, tol) and Near(gz, ez, tol), P2S(gx, gy, gz), P2S(ex, ey, ez));
end;

function MSame(A, B: Matrix; tol: double): boolean;
var r, c: integer;
begin
  result := (MNumRows(A) = MNumRows(B)) and (MNumCols(A) = MNumCols(B));
  if not result then exit;
  for r := 0 to MNumRows(A) - 1 do begin
    for c := 0 to MNumCols(A) - 1 do begin
      if not Near(Mgetv(A, r, c), Mgetv(B, r, c), tol) then begin
        result := false;
        exit;
      end;
    end;
  end;
end;

procedure CheckM(name: string; got, expected: Matrix; tol: double);
begin
  Report(name, MSame(got, expected, tol), M2S(got), M2S(expected));
end;

procedure CheckC(name: string; got: TRGBAColor; r, g, b, a: integer);
begin
  Report(name, (abs(got.Red - r) <= 1) and (abs(got.Green - g) <= 1) and (abs(got.Blue - b) <= 1) and (abs(got.alpha - a) <= 1),
         C2S(got), '(' + IntToStr(r) + ',' + IntToStr(g) + ',' + IntToStr(b) + ',' + IntToStr(a) + ')');
end;

function M22(a, b, c, d: double): Matrix;
begin
  result := Mzeros(2, 2);
  Msetv(result, 0, 0, a); Msetv(result, 0, 1, b);
  Msetv(result, 1, 0, c); Msetv(result, 1, 1, d);
end;

// a rows x cols matrix from its elements, row by row
function MR(rows, cols: integer; const v: array of double): Matrix;
var r, c: integer;
begin
  result := Mzeros(rows, cols);
  for r := 0 to rows - 1 do begin
    for c := 0 to cols - 1 do begin
      Msetv(result, r, c, v[r * cols + c]);
    end;
  end;
end;

function M31(a, b, c: double): Matrix;
begin
  result := Mzeros(3, 1);
  Msetv(result, 0, 0, a); Msetv(result, 1, 0, b); Msetv(result, 2, 0, c);
end;

// rotation of angle a (rad) around z
function MRotZ(a: double): Matrix;
begin
  result := Meye(3);
  Msetv(result, 0, 0, cos(a)); Msetv(result, 0, 1, -sin(a));
  Msetv(result, 1, 0, sin(a)); Msetv(result, 1, 1, cos(a));
end;

// ---------------------------------------------------------------------------------------------- dynmatrix

procedure CheckMatrixFunctions;
var A, B, M, G: Matrix;
    nr, nc: Longword;
    i: integer;
    good: boolean;
begin
  A := M22(1, 2, 3, 4);
  B := M22(5, 6, 7, 8);

  try
    M := Mzeros(3, 2);
    good := (MNumRows(M) = 3) and (MNumCols(M) = 2);
    for i := 0 to 5 do begin
      if good then good := Mgetv(M, i div 2, i mod 2) = 0;
    end;
    Report('Mzeros', good, M2S(M), '[3x2: 0 0; 0 0; 0 0]');
  except ReportException('Mzeros'); end;
  try CheckF('MNumRows', MNumRows(Mzeros(3, 2)), 3, 0); except ReportException('MNumRows'); end;
  try CheckF('MNumCols', MNumCols(Mzeros(3, 2)), 2, 0); except ReportException('MNumCols'); end;
  // dynmatrix's MTestData and MIsGood compare Length(data) with rows*cols*SizeOf(double) (a left-over from
  // when data was a string), on every platform: give them a matrix whose data is that long
  G.rows := 1; G.cols := 1;
  SetLength(G.data, 8);
  try
    MTestData(G, nr, nc);
    Report('MTestData', (nr = 1) and (nc = 1), IntToStr(nr) + 'x' + IntToStr(nc), '1x1');
  except ReportException('MTestData'); end;
  try CheckF('Mgetv', Mgetv(A, 1, 0), 3, 0); except ReportException('Mgetv'); end;
  try CheckF('MUgetv', MUgetv(A, 0, 1), 2, 0); except ReportException('MUgetv'); end;
  try
    good := MIsGood(G) and not MIsGood(Mzeros(0, 0));
    Report('MIsGood', good, IntToStr(ord(MIsGood(G))) + IntToStr(ord(MIsGood(Mzeros(0, 0)))), '10');
  except ReportException('MIsGood'); end;
  try CheckM('Meye', Meye(2), M22(1, 0, 0, 1), 0); except ReportException('Meye'); end;
  try
    M := Mrandom(3, 4);
    good := (MNumRows(M) = 3) and (MNumCols(M) = 4) and (Mmin(M) >= 0) and (Mmax(M) <= 1) and (Mmax(M) > Mmin(M));
    Report('Mrandom', good, M2S(M), '[3x4_in_0..1]');
  except ReportException('Mrandom'); end;
  try CheckM('Minc', Minc(2, 2), M22(0, 1, 2, 3), 0); except ReportException('Minc'); end;
  try CheckM('Madd', Madd(A, B), M22(6, 8, 10, 12), 0); except ReportException('Madd'); end;
  try CheckM('MaddReal', MaddReal(A, 0.5), M22(1.5, 2.5, 3.5, 4.5), 0); except ReportException('MaddReal'); end;
  try CheckM('Mneg', Mneg(A), M22(-1, -2, -3, -4), 0); except ReportException('Mneg'); end;
  try CheckM('Msub', Msub(B, A), M22(4, 4, 4, 4), 0); except ReportException('Msub'); end;
  try CheckM('MsubReal', MsubReal(A, 1), M22(0, 1, 2, 3), 0); except ReportException('MsubReal'); end;
  try CheckM('MmultReal', MmultReal(A, 2), M22(2, 4, 6, 8), 0); except ReportException('MmultReal'); end;
  try CheckM('Mmult', Mmult(A, B), M22(19, 22, 43, 50), 0); except ReportException('Mmult'); end;
  try CheckM('MPower', MPower(A, 3), M22(37, 54, 81, 118), 1e-9); except ReportException('MPower'); end;
  try CheckM('Mtran', Mtran(A), M22(1, 3, 2, 4), 0); except ReportException('Mtran'); end;
  try CheckM('Minv', Minv(M22(4, 7, 2, 6)), M22(0.6, -0.7, -0.2, 0.4), 1e-9); except ReportException('Minv'); end;
  try CheckM('Minv_fast', Minv_fast(M22(4, 7, 2, 6)), M22(0.6, -0.7, -0.2, 0.4), 1e-9); except ReportException('Minv_fast'); end;
  try CheckM('MelementMult', MelementMult(A, B), M22(5, 12, 21, 32), 0); except ReportException('MelementMult'); end;
  try CheckF('Mmin', Mmin(M22(3, -2, 7, 1)), -2, 0); except ReportException('Mmin'); end;
  try CheckF('Mmax', Mmax(M22(3, -2, 7, 1)), 7, 0); except ReportException('Mmax'); end;
  try CheckF('MmaxAbs', MmaxAbs(M22(3, -9, 7, 1)), 9, 0); except ReportException('MmaxAbs'); end;
  try CheckF('MallNorm', MallNorm(M22(1, 2, 2, 4)), 5, 1e-12); except ReportException('MallNorm'); end;
  try CheckM('MHflip', MHflip(A), M22(2, 1, 4, 3), 0); except ReportException('MHflip'); end;
  try
    // row convolution [1 2] * [1 1 1] = [1 3 3 2]
    M := Mzeros(1, 2); Msetv(M, 0, 0, 1); Msetv(M, 0, 1, 2);
    B := Mzeros(1, 3); Msetv(B, 0, 0, 1); Msetv(B, 0, 1, 1); Msetv(B, 0, 2, 1);
    A := Mzeros(1, 4); Msetv(A, 0, 0, 1); Msetv(A, 0, 1, 3); Msetv(A, 0, 2, 3); Msetv(A, 0, 3, 2);
    CheckM('MConv', MConv(M, B), A, 0);
  except ReportException('MConv'); end;
  A := M22(1, 2, 3, 4);
  B := M22(5, 6, 7, 8);
  try CheckM('MCrop', MCrop(Minc(3, 3), 1, 1, 2, 2), M22(4, 5, 7, 8), 0); except ReportException('MCrop'); end;
  try CheckM('MOneCol', MOneCol(Minc(3, 3), 2), M31(2, 5, 8), 0); except ReportException('MOneCol'); end;
  try CheckM('MOneRow', MOneRow(Minc(3, 3), 1), Mtran(M31(3, 4, 5)), 0); except ReportException('MOneRow'); end;
  try
    M := MStamp(Mzeros(3, 3), A, 1, 1);
    good := (Mgetv(M, 0, 0) = 0) and (Mgetv(M, 1, 1) = 1) and (Mgetv(M, 1, 2) = 2) and (Mgetv(M, 2, 1) = 3) and (Mgetv(M, 2, 2) = 4);
    Report('MStamp', good and (MNumRows(M) = 3), M2S(M), '[3x3: 0 0 0; 0 1 2; 0 3 4]');
  except ReportException('MStamp'); end;
  try CheckM('MStampCol', MStampCol(Mzeros(3, 2), M31(7, 8, 9), 1), MR(3, 2, [0, 7, 0, 8, 0, 9]), 0); except ReportException('MStampCol'); end;
  try CheckM('MStampRow', MStampRow(Mzeros(2, 3), MR(1, 3, [7, 8, 9]), 1), MR(2, 3, [0, 0, 0, 7, 8, 9]), 0); except ReportException('MStampRow'); end;
  try CheckM('MColsum', MColsum(A), MR(1, 2, [4, 6]), 0); except ReportException('MColsum'); end;
  try CheckM('MRowsum', MRowsum(A), MR(2, 1, [3, 7]), 0); except ReportException('MRowsum'); end;
  // Msave (a Matrix in) and Mload (a Matrix out): a file round trip
  try
    Msave(M22(1.5, -2, 3.25, 4), ABI_MFILE);
    M := Mload(ABI_MFILE);
    CheckM('Msave', M, M22(1.5, -2, 3.25, 4), 1e-9);
  except ReportException('Msave'); end;
  try CheckM('Mload', Mload(ABI_MFILE), M22(1.5, -2, 3.25, 4), 1e-9); except ReportException('Mload'); end;
end;

// ---------------------------------------------------------------------------------------------- Editor / Utils / Sheets / PathFinder / cameras

procedure CheckEditorFunctions;
var S: Matrix;
    p: TPoint;
    n, x, y: integer;
    good: boolean;
begin
  try
    // 2x2 surface [1 2; 3 4] over [0,1]x[0,1]: at x=0.5, y=0.25 -> 1.5 + 0.25 * (3.5 - 1.5) = 2
    CheckF('BiLinInterp', BiLinInterp(M22(1, 2, 3, 4), 0, 1, 0, 1, 0.5, 0.25), 2, 1e-9);
  except ReportException('BiLinInterp'); end;

  S := M22(1.25, -2.5, 3.75, 4);
  try
    MatrixToRange(30, 10, S);
    // RangeToMatrix is checked against GetRCValue (a double per cell), MatrixToRange against RangeToMatrix
    good := Near(GetRCValue(30, 10), 1.25, 1e-9) and Near(GetRCValue(30, 11), -2.5, 1e-9) and
            Near(GetRCValue(31, 10), 3.75, 1e-9) and Near(GetRCValue(31, 11), 4, 1e-9);
    Report('MatrixToRange', good, '(' + F2S(GetRCValue(30, 10)) + ',' + F2S(GetRCValue(30, 11)) + ',' +
           F2S(GetRCValue(31, 10)) + ',' + F2S(GetRCValue(31, 11)) + ')', '(1.25,-2.5,3.75,4)');
  except ReportException('MatrixToRange'); end;
  try CheckM('RangeToMatrix', RangeToMatrix(30, 10, 2, 2), S, 1e-9); except ReportException('RangeToMatrix'); end;
  try
    MatrixToRangeF(33, 10, M22(0.125, 2, 3, -4), '%.3f');
    good := Near(GetRCValue(33, 10), 0.125, 1e-9) and Near(GetRCValue(34, 11), -4, 1e-9);
    Report('MatrixToRangeF', good, '(' + F2S(GetRCValue(33, 10)) + ',' + F2S(GetRCValue(34, 11)) + ')', '(0.125,-4)');
  except ReportException('MatrixToRangeF'); end;

  try
    ClearAStarMap;
    SetupAStarMap(2, 3, 10, 7, 1);
    CalcAStarPath;
    n := GetAStarPathCount;
    p := GetAStarPathPoint(0);
    good := (n > 1) and (p.x = 2) and (p.y = 3);
    x := p.x; y := p.y;
    p := GetAStarPathPoint(n - 1);
    good := good and (p.x = 10) and (p.y = 7);
    Report('GetAStarPathPoint', good, '(' + IntToStr(x) + ',' + IntToStr(y) + ')..(' + IntToStr(p.x) + ',' + IntToStr(p.y) + ')/' + IntToStr(n),
           '(2,3)..(10,7)');
  except ReportException('GetAStarPathPoint'); end;

end;


// GetCameraPixel reads the camera image; SimTwo renders it only while its Cameras window is open (Ctrl+A in the
// viewer, which a headless run presses with xdotool). The check (CameraCheck, called every cycle) waits up to
// ABI_CAMERA_WAIT cycles for a non-black centre pixel, then wants three pixels with every component in 0..255.
// There is no independent copy of the image to compare with: CamBitmap.Canvas.Pixels reads black on gtk2 even
// while the camera renders. So this check is weaker than the other TRGBAColor ones (exact round trips); before
// the fix the call raised an access violation (the function read X = the result pointer). With the Cameras
// window closed the image stays black, and the check says so and passes on a black pixel.
function CameraCheck(force: boolean): boolean;
var c: TRGBAColor;
    ip, x, y: integer;
    good, lit: boolean;
    got: string;
begin
  result := false;
  try
    c := GetCameraPixel(320, 240);
    lit := (c.Red <> 0) or (c.Green <> 0) or (c.Blue <> 0);
    if not (lit or force) then exit;
    result := true;
    good := true;
    got := '';
    for ip := 0 to 2 do begin
      x := 100 + 220 * ip;
      y := 80 + 160 * ip;
      c := GetCameraPixel(x, y);
      got := got + C2S(c);
      good := good and (c.Red >= 0) and (c.Red <= 255) and (c.Green >= 0) and (c.Green <= 255) and
              (c.Blue >= 0) and (c.Blue <= 255) and (c.alpha >= 0) and (c.alpha <= 255);
    end;
    if not lit then WriteLn('ABI note: the camera image is black (Cameras window closed?)');
    Report('GetCameraPixel', good, got, '3_pixels_in_0..255');
  except
    ReportException('GetCameraPixel');
    result := true;
  end;
end;

// ---------------------------------------------------------------------------------------------- float types (not records)

procedure CheckFloatFunctions;
begin
  try CheckF('arcsin', arcsin(0.5), ABI_PI / 6, 1e-9); except ReportException('arcsin'); end;
  try CheckF('arccos', arccos(0.5), ABI_PI / 3, 1e-9); except ReportException('arccos'); end;
  try CheckF('tan', tan(ABI_PI / 4), 1, 1e-9); except ReportException('tan'); end;
  try CheckF('Power', Power(2, 10), 1024, 1e-9); except ReportException('Power'); end;
  try CheckF('Log10', Log10(1000), 3, 1e-9); except ReportException('Log10'); end;
  try CheckF('LogN', LogN(2, 8), 3, 1e-9); except ReportException('LogN'); end;
  try CheckF('RandG', RandG(5, 0), 5, 1e-9); except ReportException('RandG'); end;
  try CheckF('FloatAsInteger', FloatAsInteger(1.0), 1065353216, 0); except ReportException('FloatAsInteger'); end;
  try CheckF('IntegerAsFloat', IntegerAsFloat(1069547520), 1.5, 0); except ReportException('IntegerAsFloat'); end;
end;

// ---------------------------------------------------------------------------------------------- robot, solids, sensors, shells

procedure CheckRobotReadOnly;
var s: TState2D;
    p: TPoint3D;
    M: Matrix;
    i, iSolenoid: integer;
    mx, my, mz, msum, mi, th, d: double;
begin
  try
    s := GetRobotPos2D(RAGV);
    CheckP('GetRobotPos2D', s.x, s.y, s.angle, GetRobotX(RAGV), GetRobotY(RAGV), GetRobotTheta(RAGV), 1e-9);
  except ReportException('GetRobotPos2D'); end;

  try
    p := GetSolidPos(RAGV, iBase);
    CheckP('GetSolidPos', p.x, p.y, p.z, GetSolidX(RAGV, iBase), GetSolidY(RAGV, iBase), GetSolidZ(RAGV, iBase), 1e-9);
  except ReportException('GetSolidPos'); end;

  try
    M := GetSolidPosMat(RAGV, iBase);
    CheckM('GetSolidPosMat', M, M31(GetSolidX(RAGV, iBase), GetSolidY(RAGV, iBase), GetSolidZ(RAGV, iBase)), 1e-9);
  except ReportException('GetSolidPosMat'); end;

  try
    th := GetSolidTheta(RAGV, iBase);
    M := GetSolidRotMat(RAGV, iBase);
    // the AGV stands on the floor: a rotation around z by its theta
    // (it leans on its caster by about 0.01 rad)
    CheckM('GetSolidRotMat', M, MRotZ(th), 0.02);
  except ReportException('GetSolidRotMat'); end;

  try
    mx := 0; my := 0; mz := 0; msum := 0;
    for i := 0 to 2 do begin
      mi := GetSolidMass(RAGV, i);
      mx := mx + mi * GetSolidX(RAGV, i);
      my := my + mi * GetSolidY(RAGV, i);
      mz := mz + mi * GetSolidZ(RAGV, i);
      msum := msum + mi;
    end;
    p := GetRobotCenterOfMass(RAGV);
    CheckP('GetRobotCenterOfMass', p.x, p.y, p.z, mx / msum, my / msum, mz / msum, 1e-9);
  except ReportException('GetRobotCenterOfMass'); end;

  try
    // ODE keeps a body's centre of mass at its origin
    p := GetSolidCenterOfMass(RAGV, iBase);
    CheckP('GetSolidCenterOfMass', p.x, p.y, p.z, 0, 0, 0, 1e-12);
  except ReportException('GetSolidCenterOfMass'); end;

  try
    // AGV.xml: BasePlate size RobotLength x RobotWidth x RobotThickness
    p := GetSolidSize(RAGV, iBase);
    CheckP('GetSolidSize', p.x, p.y, p.z, 0.14, 0.105, 0.003, 1e-9);
  except ReportException('GetSolidSize'); end;

  try
    // the solenoid shell sits about RobotLength/2 + 0.01 = 0.08 m ahead of the base plate, at its height
    iSolenoid := 1;
    p := GetShellPos(RAGV, iSolenoid);
    th := GetSolidTheta(RAGV, iBase);
    d := (p.x - GetSolidX(RAGV, iBase)) * cos(th) + (p.y - GetSolidY(RAGV, iBase)) * sin(th);
    Report('GetShellPos', Near(d, 0.08, 0.003) and Near(p.z, GetSolidZ(RAGV, iBase), 0.003),
           P2S(p.x, p.y, p.z) + '/ahead=' + F2S(d), 'ahead=0.08,z=' + F2S(GetSolidZ(RAGV, iBase)));
  except ReportException('GetShellPos'); end;

  try
    // sensor 0: its measures, first one = GetSensorVal
    M := GetSensorValues(RAGV, 0);
    Report('GetSensorValues', (MNumRows(M) >= 1) and (MNumCols(M) = 1) and Near(Mgetv(M, 0, 0), GetSensorVal(RAGV, 0), 1e-9),
           M2S(M), '[nx1: ' + F2S(GetSensorVal(RAGV, 0)) + ' ...]');
  except ReportException('GetSensorValues'); end;
end;

procedure CheckRobotVelocities;
var s: TState2D;
    p: TPoint3D;
begin
  // velocities are 0 at rest: give the base plate known ones first (no physics step runs in between)
  try
    SetSolidLinearVel(RAGV, iBase, 0.1, 0.2, 0.05);
    SetSolidAngularVel(RAGV, iBase, 0.01, 0.02, 0.3);
  except ReportException('SetSolidLinearVel'); end;

  try
    s := GetRobotVel2D(RAGV);
    CheckP('GetRobotVel2D', s.x, s.y, s.angle, 0.1, 0.2, 0.3, 1e-9);
  except ReportException('GetRobotVel2D'); end;
  try
    p := GetSolidLinearVel(RAGV, iBase);
    CheckP('GetSolidLinearVel', p.x, p.y, p.z, 0.1, 0.2, 0.05, 1e-9);
  except ReportException('GetSolidLinearVel'); end;
  try CheckM('GetSolidLinearVelMat', GetSolidLinearVelMat(RAGV, iBase), M31(0.1, 0.2, 0.05), 1e-9); except ReportException('GetSolidLinearVelMat'); end;
  try CheckM('GetSolidAgularVelMat', GetSolidAgularVelMat(RAGV, iBase), M31(0.01, 0.02, 0.3), 1e-9); except ReportException('GetSolidAgularVelMat'); end;

  SetSolidLinearVel(RAGV, iBase, 0, 0, 0);
  SetSolidAngularVel(RAGV, iBase, 0, 0, 0);
end;

procedure CheckColors;
var c: TRGBAColor;
begin
  try
    SetSolidColor(RAGV, iBase, 10, 20, 30);
    c := GetSolidColor(RAGV, iBase);
    CheckC('GetSolidColor', c, 10, 20, 30, 255);
  except ReportException('GetSolidColor'); end;
  try
    SetShellColor(RAGV, 1, 40, 50, 60);
    c := GetShellColor(RAGV, 1);
    CheckC('GetShellColor', c, 40, 50, 60, 255);
  except ReportException('GetShellColor'); end;
end;

// ---------------------------------------------------------------------------------------------- axes

procedure CheckAxesReadOnly;
var st: TAxisState;
    mp: TMotorPars;
    cp: TMotorControllerPars;
    fd: TFrictionDef;
    ap: TAxisPoint;
    good, loaded: boolean;
begin
  try
    st := GetAxisState(RAGV, iLeftAxis);
    Report('GetAxisState', Near(st.pos, GetAxisPos(RAGV, iLeftAxis), 1e-9) and Near(st.vel, GetAxisSpeed(RAGV, iLeftAxis), 1e-9) and
           Near(st.Torque, GetAxisTorque(RAGV, iLeftAxis), 1e-9) and Near(st.Vm, GetAxisU(RAGV, iLeftAxis), 1e-9) and
           Near(st.Im, GetAxisI(RAGV, iLeftAxis), 1e-9),
           '(' + F2S(st.pos) + ',' + F2S(st.vel) + ',' + F2S(st.Torque) + ',' + F2S(st.Vm) + ',' + F2S(st.Im) + ')',
           '(' + F2S(GetAxisPos(RAGV, iLeftAxis)) + ',' + F2S(GetAxisSpeed(RAGV, iLeftAxis)) + ',' + F2S(GetAxisTorque(RAGV, iLeftAxis)) + ',' +
           F2S(GetAxisU(RAGV, iLeftAxis)) + ',' + F2S(GetAxisI(RAGV, iLeftAxis)) + ')');
  except ReportException('GetAxisState'); end;

  try
    SetAxisPosRef(RAGV, iLeftAxis, 0.7);
    SetAxisSpeedRef(RAGV, iLeftAxis, -0.3);
    st := GetAxisStateRef(RAGV, iLeftAxis);
    Report('GetAxisStateRef', Near(st.pos, 0.7, 1e-12) and Near(st.vel, -0.3, 1e-12), '(' + F2S(st.pos) + ',' + F2S(st.vel) + ')', '(0.7,-0.3)');
  except ReportException('GetAxisStateRef'); end;

  try
    // AGV.xml <motor ri='6.1' li='3.4e-3' ki='0.2585' vmax='8.2' imax='3' active='1'/> <gear ratio='1'/>
    mp := GetMotorPars(RAGV, iLeftAxis);
    good := Near(mp.Ri, 6.1, 1e-9) and Near(mp.Li, 3.4e-3, 1e-12) and Near(mp.Ki, 0.2585, 1e-9) and Near(mp.Vmax, 8.2, 1e-9) and
            Near(mp.Imax, 3, 1e-9) and Near(mp.GearRatio, 1, 1e-9) and mp.active;
    Report('GetMotorPars', good, '(' + F2S(mp.Ri) + ',' + F2S(mp.Li) + ',' + F2S(mp.Ki) + ',' + F2S(mp.Vmax) + ',' + F2S(mp.Imax) + ',' +
           F2S(mp.GearRatio) + ',' + IntToStr(ord(mp.active)) + ')', '(6.1,0.0034,0.2585,8.2,3,1,1)');
  except ReportException('GetMotorPars'); end;

  try
    // AGV.xml <controller mode='pidspeed' kp='1' ki='0' kd='0' kf='0.05'/>
    cp := GetMotorControllerPars(RAGV, iLeftAxis);
    Report('GetMotorControllerPars', Near(cp.Ki, 0, 1e-12) and Near(cp.Kd, 0, 1e-12) and Near(cp.Kp, 1, 1e-12) and Near(cp.Kf, 0.05, 1e-12),
           '(' + F2S(cp.Ki) + ',' + F2S(cp.Kd) + ',' + F2S(cp.Kp) + ',' + F2S(cp.Kf) + ')', '(0,0,1,0.05)');
  except ReportException('GetMotorControllerPars'); end;

  try
    // AGV.xml <friction bv='0.0012' fc='0.0169'/> (CoulombLimit is not returned by GetFrictionDef)
    fd := GetFrictionDef(RAGV, iLeftAxis);
    Report('GetFrictionDef', Near(fd.Bv, 0.0012, 1e-12) and Near(fd.Fc, 0.0169, 1e-12), '(' + F2S(fd.Bv) + ',' + F2S(fd.Fc) + ')', '(0.0012,0.0169)');
  except ReportException('GetFrictionDef'); end;

  // GetJointWayPoint needs a joint way-point file, which a script cannot write on this build (TStrings.SaveToFile,
  // SaveToStream and TFileStream.Create raise access violations from PascalScript under FPC 3.2). It is checked
  // only when the scene folder holds abi_check_waypoints.xml with a single state for LeftAxis:
  //   <?xml version="1.0"?>
  //   <joint_waypoints><state ID="abi" final_time="2"><joint ID="LeftAxis" theta="10" w="5"/></state></joint_waypoints>
  try
    LoadJointWayPoints(RAGV, ABI_WPFILE);
    loaded := CountJointWayPoints(RAGV, iLeftAxis) > 0;
  except
    loaded := false;  // no such file: not checked
  end;
  if loaded then begin
    try
      ap := GetJointWayPoint(RAGV, iLeftAxis, 0);
      CheckP('GetJointWayPoint', ap.pos, ap.speed, ap.final_time, 10 * ABI_PI / 180, 5 * ABI_PI / 180, 2, 1e-9);
    except ReportException('GetJointWayPoint'); end;
  end;
end;

procedure CheckAxesWrites;
var st: TAxisState;
    mp, mp2: TMotorPars;
    cp: TMotorControllerPars;
    fd: TFrictionDef;
    ap: TAxisPoint;
    n: integer;
begin
  try
    st.pos := 1.25; st.vel := -0.5; st.Torque := 0; st.Vm := 0; st.Im := 0;
    SetAxisStateRef(RAGV, iLeftAxis, st);
    CheckP('SetAxisStateRef', GetAxisPosRef(RAGV, iLeftAxis), GetAxisSpeedRef(RAGV, iLeftAxis), 0, 1.25, -0.5, 0, 1e-12);
  except ReportException('SetAxisStateRef'); end;
  SetAxisPosRef(RAGV, iLeftAxis, 0);
  SetAxisSpeedRef(RAGV, iLeftAxis, 0);

  try
    SetMotorControllerPars(RAGV, iLeftAxis, 0.11, 0.22, 0.33, 0.44);
    cp := GetMotorControllerPars(RAGV, iLeftAxis);
    Report('GetMotorControllerPars(set)', Near(cp.Ki, 0.11, 1e-12) and Near(cp.Kd, 0.22, 1e-12) and Near(cp.Kp, 0.33, 1e-12) and Near(cp.Kf, 0.44, 1e-12),
           '(' + F2S(cp.Ki) + ',' + F2S(cp.Kd) + ',' + F2S(cp.Kp) + ',' + F2S(cp.Kf) + ')', '(0.11,0.22,0.33,0.44)');
    SetMotorControllerPars(RAGV, iLeftAxis, 0, 0, 1, 0.05);
  except ReportException('GetMotorControllerPars(set)'); end;

  try
    SetFrictionDef(RAGV, iLeftAxis, 0.002, 0.03, 0);
    fd := GetFrictionDef(RAGV, iLeftAxis);
    Report('GetFrictionDef(set)', Near(fd.Bv, 0.002, 1e-12) and Near(fd.Fc, 0.03, 1e-12), '(' + F2S(fd.Bv) + ',' + F2S(fd.Fc) + ')', '(0.002,0.03)');
    SetFrictionDef(RAGV, iLeftAxis, 0.0012, 0.0169, 0);
  except ReportException('GetFrictionDef(set)'); end;

  try
    mp := GetMotorPars(RAGV, iLeftAxis);
    mp2 := mp;
    mp2.Ri := 5.5; mp2.Li := 0.002; mp2.Ki := 0.3; mp2.Vmax := 9; mp2.Imax := 2.5; mp2.GearRatio := 2; mp2.active := false;
    SetMotorPars(RAGV, iLeftAxis, mp2);
    // IsMotorActive is a boolean getter independent of the record result; GetMotorPars is checked above
    mp2 := GetMotorPars(RAGV, iLeftAxis);
    Report('SetMotorPars', Near(mp2.Ri, 5.5, 1e-12) and Near(mp2.Li, 0.002, 1e-12) and Near(mp2.Ki, 0.3, 1e-12) and Near(mp2.Vmax, 9, 1e-12) and
           Near(mp2.Imax, 2.5, 1e-12) and Near(mp2.GearRatio, 2, 1e-12) and (not IsMotorActive(RAGV, iLeftAxis)),
           '(' + F2S(mp2.Ri) + ',' + F2S(mp2.Li) + ',' + F2S(mp2.Ki) + ',' + F2S(mp2.Vmax) + ',' + F2S(mp2.Imax) + ',' + F2S(mp2.GearRatio) + ',' +
           IntToStr(ord(IsMotorActive(RAGV, iLeftAxis))) + ')', '(5.5,0.002,0.3,9,2.5,2,0)');
    SetMotorPars(RAGV, iLeftAxis, mp);
    SetMotorActive(RAGV, iLeftAxis, true);
  except ReportException('SetMotorPars'); end;

  try
    ClearAxisTrajPoints(RAGV, iLeftAxis);
    ap.pos := 1.5; ap.speed := -2.5; ap.final_time := 3.5;
    AddAxisTrajPoint(RAGV, iLeftAxis, ap);
    n := CountAxisTrajPoints(RAGV, iLeftAxis);
    ap := GetAxisTrajPoint(RAGV, iLeftAxis, 0);
    Report('AddAxisTrajPoint', (n = 1) and Near(ap.pos, 1.5, 1e-12) and Near(ap.speed, -2.5, 1e-12) and Near(ap.final_time, 3.5, 1e-12),
           IntToStr(n) + P2S(ap.pos, ap.speed, ap.final_time), '1' + P2S(1.5, -2.5, 3.5));
  except ReportException('AddAxisTrajPoint'); end;

  try
    // a trajectory point made with the double-only SetJointWayPoint path is not available; GetAxisTrajPoint
    // reads what AddAxisTrajPoint stored (checked with CountAxisTrajPoints) and what SetAxisTrajPoint changes
    ap := GetAxisTrajPoint(RAGV, iLeftAxis, 0);
    CheckP('GetAxisTrajPoint', ap.pos, ap.speed, ap.final_time, 1.5, -2.5, 3.5, 1e-12);
  except ReportException('GetAxisTrajPoint'); end;

  try
    ap.pos := -0.25; ap.speed := 0.75; ap.final_time := 4.5;
    SetAxisTrajPoint(RAGV, iLeftAxis, 0, ap);
    ap := GetAxisTrajPoint(RAGV, iLeftAxis, 0);
    CheckP('SetAxisTrajPoint', ap.pos, ap.speed, ap.final_time, -0.25, 0.75, 4.5, 1e-12);
  except ReportException('SetAxisTrajPoint'); end;
  ClearAxisTrajPoints(RAGV, iLeftAxis);
end;

// ---------------------------------------------------------------------------------------------- things and obstacles

procedure CheckThings;
var t: integer;
    p: TPoint3D;
    c: TRGBAColor;
begin
  try
    t := AddThingBox('abi_box', 0.1, 0.5, 0.6, 0.05, 0.02, 0.03, 0.04, $0000FF);
  except
    ReportException('AddThingBox');
    exit;
  end;

  try p := GetThingPos(t); CheckP('GetThingPos', p.x, p.y, p.z, 0.5, 0.6, 0.05, 1e-9); except ReportException('GetThingPos'); end;
  try p := GetThingSize(t); CheckP('GetThingSize', p.x, p.y, p.z, 0.02, 0.03, 0.04, 1e-9); except ReportException('GetThingSize'); end;
  try
    SetThingColor(t, 0, 70, 80, 90);
    c := GetThingColor(t, 0);
    CheckC('GetThingColor', c, 70, 80, 90, 255);
  except ReportException('GetThingColor'); end;
  try
    SetThingLinearVel(t, 0.1, 0.2, 0.3);
    p := GetThingSpeed(t);
    CheckP('GetThingSpeed', p.x, p.y, p.z, 0.1, 0.2, 0.3, 1e-9);
  except ReportException('GetThingSpeed'); end;
  try
    SetThingAngularVel(t, 0.4, 0.5, 0.6);
    p := GetThingAngularVel(t);
    CheckP('GetThingAngularVel', p.x, p.y, p.z, 0.4, 0.5, 0.6, 1e-9);
  except ReportException('GetThingAngularVel'); end;
  try CheckM('GetThingAgularVelMat', GetThingAgularVelMat(t), M31(0.4, 0.5, 0.6), 1e-9); except ReportException('GetThingAgularVelMat'); end;
  try CheckM('GetThingRotMat', GetThingRotMat(t), Meye(3), 1e-9); except ReportException('GetThingRotMat'); end;
  try
    SetThingRotationMat(t, MRotZ(0.5));
    CheckM('SetThingRotationMat', GetThingRotMat(t), MRotZ(0.5), 1e-6);
  except ReportException('SetThingRotationMat'); end;
  DeleteThing('abi_box');
end;

procedure CheckObstacles;
var o: integer;
    p: TPoint3D;
    c: TRGBAColor;
begin
  try
    o := AddOBstacleBox('abi_obstacle', 0.3, -0.2, 0.5, 0.01, 0.02, 0.03, $00FF00);
  except
    ReportException('AddOBstacleBox');
    exit;
  end;
  try p := GetObstaclePos(o); CheckP('GetObstaclePos', p.x, p.y, p.z, 0.3, -0.2, 0.5, 1e-9); except ReportException('GetObstaclePos'); end;
  try
    SetObstacleColor(o, 15, 25, 35);
    c := GetObstacleColor(o);
    CheckC('GetObstacleColor', c, 15, 25, 35, 255);
  except ReportException('GetObstacleColor'); end;
  try CheckM('GetObstacleRotMat', GetObstacleRotMat(o), Meye(3), 1e-9); except ReportException('GetObstacleRotMat'); end;
  try
    SetObstacleRotationMat(o, MRotZ(-0.4));
    CheckM('SetObstacleRotationMat', GetObstacleRotMat(o), MRotZ(-0.4), 1e-6);
  except ReportException('SetObstacleRotationMat'); end;
  DeleteObstacle('abi_obstacle');
end;

// ---------------------------------------------------------------------------------------------- solid pose setters (last)

procedure CheckSolidSetters;
var x, y, z, th: double;
    R0: Matrix;
begin
  x := GetSolidX(RAGV, iBase);
  y := GetSolidY(RAGV, iBase);
  z := GetSolidZ(RAGV, iBase);
  th := GetSolidTheta(RAGV, iBase);
  R0 := GetSolidRotMat(RAGV, iBase);
  try
    SetSolidPosMat(RAGV, iBase, M31(x + 0.01, y - 0.02, z + 0.003));
    CheckP('SetSolidPosMat', GetSolidX(RAGV, iBase), GetSolidY(RAGV, iBase), GetSolidZ(RAGV, iBase), x + 0.01, y - 0.02, z + 0.003, 1e-9);
  except ReportException('SetSolidPosMat'); end;
  SetSolidPos(RAGV, iBase, x, y, z);
  try
    SetSolidRotationMat(RAGV, iBase, MRotZ(th + 0.3));
    CheckF('SetSolidRotationMat', GetSolidTheta(RAGV, iBase), th + 0.3, 1e-6);
  except ReportException('SetSolidRotationMat'); end;
  SetSolidRotationMat(RAGV, iBase, R0);
end;

// ---------------------------------------------------------------------------------------------- main

procedure RunAbiChecks;
begin
  nOk := 0;
  nFail := 0;
  RAGV := GetRobotIndex('AGV');
  iBase := GetSolidIndex(RAGV, 'BasePlate');
  iLeftAxis := GetAxisIndex(RAGV, 'LeftAxis', 0);
  WriteLn('ABI start robot=' + IntToStr(RAGV) + ' base=' + IntToStr(iBase) + ' axis=' + IntToStr(iLeftAxis));

  CheckMatrixFunctions;
  CheckEditorFunctions;  // GetCameraPixel: later, see CameraCheck
  CheckRobotReadOnly;
  CheckAxesReadOnly;
  CheckRobotVelocities;
  CheckColors;
  CheckThings;
  CheckObstacles;
  CheckAxesWrites;
  CheckSolidSetters;
  // last: before patch 14 the Extended calls left their results on the x87 stack, which broke later native
  // maths (after six of them GetRobotPos2D's angle was NaN)
  CheckFloatFunctions;
end;

procedure Initialize;
begin
  AbiDone := false;
  AbiCamera := false;
  AbiCycle := 0;
end;

procedure Control;
begin
  if AbiDone then exit;
  AbiCycle := AbiCycle + 1;
  if AbiCycle = ABI_START then RunAbiChecks;
  if AbiCycle < ABI_START then exit;
  if not AbiCamera then AbiCamera := CameraCheck(AbiCycle >= ABI_START + ABI_CAMERA_WAIT);
  if AbiCamera then begin
    AbiDone := true;
    WriteLn('ABI done ' + IntToStr(nOk) + ' ' + IntToStr(nFail));
  end;
end;
