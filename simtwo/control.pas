// robotatfactory -- SimTwo scene script for the RobotAtFactory 4.0 scene (RobotFactoryPro2022).
//
// Every control cycle (the script period, 40 ms) this script
//   1. reads both encoders (GetAxisOdo: ticks since the previous cycle), the ground truth
//      (GetRobotX/Y/Theta), the contact switch, the LIDAR (GetSensorValues of a ranger2d) and
//      the ground truth of the scene's parts Part1..PartN (for a referee: `raf referee`);
//   2. sends them to the ROS bridge (`raf bridge`) as one SensorFrame datagram, exactly as
//      docs/protocol.md (protocol version 1) defines it: labelled strings, CR LF line ends,
//      integers %d, reals %.6g with a '.' decimal point whatever the Windows locale;
//   3. reads the bridge's Command reply (V, W, S; the first occurrence of a label wins, as
//      ReadUDPData concatenates everything received since the previous call), checks its
//      protocol version and Seq, turns V and W into wheel speed references for SimTwo's own
//      speed controller (SetAxisSpeedRef) and switches the electromagnet (SetSensorVin).
// A missing or garbled reply keeps the last command; no valid command for COMMAND_TIMEOUT_MS
// of simulation time stops the wheels. Nothing here ever waits.
//
// Timing: SimTwo runs this script and receives UDP on the same (GUI) thread, so no datagram can
// arrive while Control runs. The reply to the frame sent in cycle n is read and applied in cycle
// n+1 (40 ms later); waiting for it inside Control would only stall SimTwo. (There is no lockstep.)
//
// Written for SimTwo's script engine, RemObjects PascalScript, as SimTwo sets it up: the header
// `const MaxDim = 8; const k = MaxDim-1;` comes before this file, so no identifier here may be
// MaxDim or k (PascalScript refuses a local that repeats a global: "Duplicate identifier");
// `and`/`or` short-circuit (icBooleanShortCircuit); Format writes '.' as the decimal point (SimTwo
// sets it at start-up, whatever the Windows locale). Plain procedural code: no classes, no nested
// routines. Settings: the constants below.
// docs/simtwo.md explains the installation; tests/test_simtwo_pascalscript.py compiles this very
// file with PascalScript, registered as SimTwo registers its script API, and runs it against a
// stand-in of that API (simtwo/test/).

const
  // ---- where the bridge is ----------------------------------------------------------------
  BRIDGE_IP = '127.0.0.1';     // the machine running `raf bridge` (its IPv4 address)
  BRIDGE_PORT = 9810;          // the bridge's UDP port (SimTwo itself listens on 9808, I/O tab)

  // ---- the reply -------------------------------------------------------------------------
  COMMAND_TIMEOUT_MS = 400;    // no valid command for this long (simulation ms): stop the wheels; with
                               // the wheels' ~80 ms ramp the robot is at rest within ~0.54 s of its last command

  // ---- the robot (AGV.xml of RobotFactoryPro2022) -----------------------------------------
  ROBOT_ID = 'AGV';            // the robot's ID in scene.xml
  LEFT_AXIS_ID = 'LeftAxis';   // axis 0
  RIGHT_AXIS_ID = 'RightAxis'; // axis 1
  CONTACT_ID = 'MicroSwitch';  // IRSharp beam: a value > 0 means something touches it
  MAGNET_ID = 'solenoid1';     // solenoid sensor, switched with SetSensorVin
  LIDAR_ID = 'ranger2d';       // the ranger2d of simtwo/AGV_lidar.xml
  WHEEL_RADIUS = 0.0325;       // m
  TRACK = 0.135;               // m, between the wheels
  MAGNET_VIN_ON = 1;           // SetSensorVin value for "on" (force 0.5 * Vin * fmax)

  // ---- the parts' ground truth (optional labels PartsN, Parts: for a referee, never the robot) --
  SEND_PARTS = 1;              // 1: report robots Part1..PartN of the scene every cycle; 0: never
  PART_PREFIX = 'Part';        // the scene's parts are robots Part1, Part2, ... (scene.xml)
  MAX_PARTS = 8;

  // ---- wheel speed control: SimTwo's own PID (CalcPID), enabled and set ONCE in Initialize ----
  // SimTwo runs it inside the physics loop every controller period (the scene's <controller
  // period='10'/>, ms) as V = KP*e + KI*S + KD*(e - e_prev)/0.001 + KF*w_ref, e = w_ref - w (rad/s
  // at the wheel), S += e * 0.001 (the 1 ms physics step, whatever the period), V clamped to the
  // motor's Vmax. SetMotorControllerState and SetMotorControllerPars both reset S to 0, which is
  // why neither is ever called again after Initialize. The gains are robot_simtwo.json's
  // "simtwo_pid" (tests/test_simtwo_pascalscript.py checks they agree).
  SET_SPEED_GAINS = 1;         // 1: set the gains below at Initialize; 0: keep the scene's
  SPEED_KP = 0.1;              // V per rad/s of error
  SPEED_KI = 100.0;            // V per (rad/s * s) of integrated error
  SPEED_KD = 0.0;              // V per rad/s^2
  SPEED_KF = 0.42;             // V per rad/s of reference

  // ---- LIDAR range noise, sigma = A * exp(B * d) metres (A = 0: SimTwo's ranges unchanged) ----
  LIDAR_NOISE_A = 0.001524;
  LIDAR_NOISE_B = 1.3103;
  LIDAR_NOISE_EVERY = 5;       // cycles per SimTwo sweep (ranger period 0.2 s / script period 40 ms)
  MAX_RAY = 1023;              // rays 0..MAX_RAY keep their noise for a sweep (more: drawn each cycle)

  // ---- protocol -----------------------------------------------------------------------------
  PROTOCOL_VERSION = 1;
  MAX_PARSE_CHARS = 2048;      // a reply is about 50 bytes; longer input is cut here
  MAX_LINES = 2048;
  LOG_EVERY = 250;             // repeated warnings: the first 3, then every 250th
  STATUS_EVERY = 1500;         // a status line every 1500 cycles (one minute)
  EOL = #13#10;

var
  // settings in effect: Initialize copies the constants (a test harness may change them after)
  CfgBridgeIP: string;
  CfgBridgePort: integer;
  CfgCommandTimeoutMs: integer;
  CfgLidarNoiseA, CfgLidarNoiseB: double;

  iRobot, iAxisLeft, iAxisRight, iContact, iMagnet, iLidar: integer;
  iParts: array[0..7] of integer;  // robot indices of Part1..PartN (MAX_PARTS at most)
  NParts: integer;

  FrameSeq: integer;           // Seq of the frame this cycle sends: 0 for the first
  TimeMs: integer;             // simulation time at the end of this cycle, ms
  OdoLeft, OdoRight: integer;  // running encoder totals since Initialize

  CmdV, CmdW: double;          // the command in effect (m/s, rad/s)
  CmdMagnet: integer;          // 0/1
  MagnetApplied: integer;      // what SetSensorVin applied during the cycle that just ended
  LastAppliedSeq: integer;     // Seq of the last accepted reply (-1: none yet)
  LastValidMs: integer;        // TimeMs when a valid reply was last accepted
  TimedOut: integer;           // 1 while the wheels are stopped for lack of commands

  NFrames, NAccepted, NRejected, NTimeouts: integer;
  LastTpId: integer;           // TpId of the last teleport applied (0: none)
  NTeleports: integer;

  // the reply being decoded
  RLines: array[0..2047] of string;
  RCount: integer;
  RNonAscii: integer;
  RepSeq, RepMagnet: integer;
  RepV, RepW: double;
  RepError: string;

  // LIDAR noise per ray: the clean value it was drawn for, the noisy value sent, this cycle's value
  LidarRaw, LidarNoisy, LidarCur: array[0..1023] of double;
  LidarDrawSeq: integer;       // FrameSeq of the last noise draw


// ---------------------------------------------------------------------------------------------
// Text helpers
// ---------------------------------------------------------------------------------------------

// %.6g with a '.' decimal point: SimTwo sets DecimalSeparator to '.' at start-up (Viewer.pas)
function FmtReal(x: double): string;
begin
  result := Format('%.6g', [x]);
end;

function LabelLine(lbl, value: string): string;
begin
  result := lbl + EOL + value + EOL + EOL;
end;

// Python's str.strip() blanks among ASCII: TAB LF VT FF CR, 28..31 and space
function IsBlank(c: char): boolean;
var o: integer;
begin
  o := Ord(c);
  result := ((o >= 9) and (o <= 13)) or ((o >= 28) and (o <= 32));
end;

function StripBlanks(s: string): string;
var a, b: integer;
    go: boolean;
begin
  a := 1;
  b := Length(s);
  go := true;
  while go do begin
    if a > b then go := false
    else if IsBlank(s[a]) then a := a + 1
    else go := false;
  end;
  go := true;
  while go do begin
    if b < a then go := false
    else if IsBlank(s[b]) then b := b - 1
    else go := false;
  end;
  result := Copy(s, a, b - a + 1);
end;

function IsDigit(c: char): boolean;
begin
  result := (c >= '0') and (c <= '9');
end;

// Skips an optional sign at s[i]; true when it was '-'.
function ReadSign(s: string; var i: integer): boolean;
begin
  result := false;
  if i <= Length(s) then
    if (s[i] = '+') or (s[i] = '-') then begin
      result := (s[i] = '-');
      i := i + 1;
    end;
end;

// Decimal digits from s[i] into the mantissa m (value = m * 10^e10), keeping at most 18 significant
// ones: further integer digits raise e10, further fraction digits are dropped; each kept fraction
// digit lowers e10. True when at least one digit was read.
function ReadMantissa(s: string; var i: integer; var m: double; var nd, e10: integer;
                      fraction: boolean): boolean;
var n: integer;
    go: boolean;
begin
  result := false;
  n := Length(s);
  go := true;
  while go do begin
    if i > n then go := false
    else if IsDigit(s[i]) then begin
      result := true;
      if nd < 18 then begin
        m := m * 10 + (Ord(s[i]) - Ord('0'));
        if m > 0 then nd := nd + 1;
        if fraction then e10 := e10 - 1;
      end else if not fraction then e10 := e10 + 1;
      i := i + 1;
    end else go := false;
  end;
end;

// An integer: optional sign, decimal digits, blanks around. At most 9 significant digits.
function ParseIntStr(s: string; var v: integer): boolean;
var i, n, nd, d: integer;
    neg, go: boolean;
begin
  result := false;
  v := 0;
  s := StripBlanks(s);
  n := Length(s);
  if n = 0 then exit;
  i := 1;
  neg := ReadSign(s, i);
  if i > n then exit;
  nd := 0;
  go := true;
  while go do begin
    if i > n then go := false
    else if IsDigit(s[i]) then begin
      d := Ord(s[i]) - Ord('0');
      if (v > 0) or (d > 0) then nd := nd + 1;
      if nd > 9 then exit;
      v := v * 10 + d;
      i := i + 1;
    end else exit;           // anything else: not an integer
  end;
  if neg then v := -v;
  result := true;
end;

// A real as Python's float() reads it (without inf/nan/underscores): [sign] digits [. digits]
// [e|E [sign] digits], or [sign] . digits [...]. Magnitudes of 1e15 and more are refused.
function ParseRealStr(s: string; var v: double): boolean;
var i, n, nd, e10, ev, ae, j: integer;
    m, p: double;
    neg, eneg, sawDigit, sawExpDigit, go: boolean;
    c: char;
begin
  result := false;
  v := 0;
  s := StripBlanks(s);
  n := Length(s);
  if n = 0 then exit;
  i := 1;
  neg := ReadSign(s, i);
  m := 0;
  nd := 0;                   // significant digits kept in m (at most 18)
  e10 := 0;                  // value = m * 10^e10
  sawDigit := ReadMantissa(s, i, m, nd, e10, false);
  if i <= n then
    if s[i] = '.' then begin
      i := i + 1;
      if ReadMantissa(s, i, m, nd, e10, true) then sawDigit := true;
    end;
  if not sawDigit then exit;
  // exponent
  if i <= n then begin
    c := s[i];
    if (c = 'e') or (c = 'E') then begin
      i := i + 1;
      eneg := ReadSign(s, i);
      ev := 0;
      sawExpDigit := false;
      go := true;
      while go do begin
        if i > n then go := false
        else if IsDigit(s[i]) then begin
          sawExpDigit := true;
          if ev < 100000 then ev := ev * 10 + (Ord(s[i]) - Ord('0'));
          i := i + 1;
        end else go := false;
      end;
      if not sawExpDigit then exit;
      if eneg then e10 := e10 - ev else e10 := e10 + ev;
    end;
  end;
  if i <= n then exit;       // trailing characters
  if m = 0 then begin
    v := 0;
    result := true;
    exit;
  end;
  if nd + e10 > 15 then exit;           // 1e15 or more: no speed is that large
  if e10 < -300 then begin
    v := 0;
    result := true;
    exit;
  end;
  ae := e10;
  if ae < 0 then ae := -ae;
  p := 1;
  for j := 1 to ae do p := p * 10;
  if e10 >= 0 then v := m * p else v := m / p;
  if neg then v := -v;
  result := true;
end;


// ---------------------------------------------------------------------------------------------
// Reading a reply: lines split on CR, LF or CR LF; a label's value is the line after the FIRST
// line equal to it (as SimTwo scripts and robotatfactory.simtwo.LabelledValues read it)
// ---------------------------------------------------------------------------------------------

procedure SplitReply(txt: string);
var i, n, start: integer;
    c: char;
begin
  RCount := 0;
  RNonAscii := 0;
  n := Length(txt);
  start := 1;
  i := 1;
  while i <= n do begin
    c := txt[i];
    if Ord(c) > 127 then RNonAscii := 1;
    if (c = #13) or (c = #10) then begin
      if RCount < MAX_LINES then begin
        RLines[RCount] := Copy(txt, start, i - start);
        RCount := RCount + 1;
      end;
      if c = #13 then begin
        if i < n then begin
          if txt[i + 1] = #10 then i := i + 1;
        end;
      end;
      start := i + 1;
    end;
    i := i + 1;
  end;
  if start <= n then begin     // a last line without a line end
    if RCount < MAX_LINES then begin
      RLines[RCount] := Copy(txt, start, n - start + 1);
      RCount := RCount + 1;
    end;
  end;
end;

function FindLabel(lbl: string; var value: string): boolean;
var i: integer;
begin
  result := false;
  value := '';
  for i := 0 to RCount - 1 do begin
    if RLines[i] = lbl then begin
      if i + 1 < RCount then begin
        value := RLines[i + 1];
        result := true;
      end;
      exit;
    end;
  end;
end;

// The integer after label lbl; false and RepError when the label is missing or the value is not one
function LabelInt(lbl: string; var v: integer): boolean;
var s: string;
begin
  result := false;
  if not FindLabel(lbl, s) then RepError := 'label ' + lbl + ' is missing'
  else if not ParseIntStr(s, v) then RepError := lbl + ' is not an integer'
  else result := true;
end;

// The real number after label lbl; false and RepError as LabelInt
function LabelReal(lbl: string; var v: double): boolean;
var s: string;
begin
  result := false;
  if not FindLabel(lbl, s) then RepError := 'label ' + lbl + ' is missing'
  else if not ParseRealStr(s, v) then RepError := lbl + ' is not a real number'
  else result := true;
end;

// Decodes a Command (RAF, Seq, V, W, S) into RepSeq, RepV, RepW, RepMagnet; false and RepError
// when anything is missing or malformed (the whole reply is then ignored)
function DecodeReply(txt: string): boolean;
var s: string;
    raf: integer;
begin
  result := false;
  RepError := '';
  if Length(txt) > MAX_PARSE_CHARS then txt := Copy(txt, 1, MAX_PARSE_CHARS);
  SplitReply(txt);
  if RNonAscii = 1 then begin
    RepError := 'bytes that are not ASCII';
    exit;
  end;
  if not FindLabel('RAF', s) then begin
    RepError := 'no RAF label (not a RobotAtFactory command)';
    exit;
  end;
  if not ParseIntStr(s, raf) then begin
    RepError := 'RAF is not an integer';
    exit;
  end;
  if raf <> PROTOCOL_VERSION then begin
    RepError := 'protocol version ' + IntToStr(raf) + '; this script speaks version ' + IntToStr(PROTOCOL_VERSION);
    exit;
  end;
  if not LabelReal('V', RepV) then exit;
  if not LabelReal('W', RepW) then exit;
  if not LabelInt('S', RepMagnet) then exit;
  if (RepMagnet <> 0) and (RepMagnet <> 1) then begin
    RepError := 'S is not 0 or 1';
    exit;
  end;
  if not LabelInt('Seq', RepSeq) then exit;
  result := true;
end;

// A reply answers a frame already sent (Seq <= FrameSeq) and newer than the last one applied;
// Seq -1 is an unsolicited command (e.g. the bridge's watchdog stop) and always accepted
function SeqAcceptable(seq: integer): boolean;
begin
  result := false;
  if seq = -1 then result := true
  else if (seq >= 0) and (seq <= FrameSeq) and (seq > LastAppliedSeq) then result := true;
end;


// ---------------------------------------------------------------------------------------------
// Logging (SimTwo's script output window), rate-limited for repeated events
// ---------------------------------------------------------------------------------------------

procedure LogMsg(msg: string);
begin
  WriteLn('raf: ' + msg);
end;

procedure LogRepeated(count: integer; msg: string);
begin
  if (count <= 3) or (count mod LOG_EVERY = 0) then
    LogMsg(msg + ' (' + IntToStr(count) + ' so far)');
end;


// ---------------------------------------------------------------------------------------------
// UDP
// ---------------------------------------------------------------------------------------------

// SimTwo keeps every datagram twice: in ReadUDPData's buffer and in ReadUDPPacket's list.
// This script reads with ReadUDPData, so it empties the list to keep it from growing.
procedure DrainPacketList;
var s: string;
    n: integer;
begin
  n := 0;
  while (GetUDPPacketCount() > 0) and (n < 10000) do begin
    s := ReadUDPPacket();
    n := n + 1;
  end;
end;


// ---------------------------------------------------------------------------------------------
// Sensors
// ---------------------------------------------------------------------------------------------

// A range as sent: -1 for no return (SimTwo's -1, or anything that is not a finite range >= 0)
function CleanRange(d: double): double;
var ok: boolean;
begin
  // written so that NaN fails the test whatever a compiler does with `not (d >= 0)`
  ok := false;
  if d >= 0 then begin
    if d < 1.0e9 then ok := true;
  end;
  if ok then result := d else result := -1;
end;

// A clean range plus noise of sigma A * exp(B * d), never below 0; -1 stays -1
function AddNoise(d: double): double;
var r: double;
begin
  if (d < 0) or (CfgLidarNoiseA <= 0) then begin
    result := d;
    exit;
  end;
  r := d + RandG(0, CfgLidarNoiseA * Exp(CfgLidarNoiseB * d));
  if r < 0 then r := 0;
  result := r;
end;

// The Lidar value line ('' without a LIDAR) and the number of rays in it.
// SimTwo delivers a whole new sweep once per ranger period (5 cycles) and returns the same values in
// between. The noise is drawn once per sweep: for every ray when the values change (a new sweep),
// or, while they repeat exactly (a robot standing still), LIDAR_NOISE_EVERY cycles after the last
// draw, which keeps to SimTwo's sweep schedule. New noise between SimTwo's sweeps would look like a
// sweep SimTwo never made.
function LidarLine(var n: integer): string;
var M: Matrix;
    i: integer;
    d: double;
    s: string;
    fresh: boolean;
begin
  s := '';
  n := 0;
  if iLidar >= 0 then begin
    M := GetSensorValues(iRobot, iLidar);
    n := MNumRows(M);
    fresh := false;
    for i := 0 to n - 1 do begin
      d := CleanRange(Mgetv(M, i, 0));
      if i <= MAX_RAY then begin
        LidarCur[i] := d;
        if d <> LidarRaw[i] then fresh := true;
      end;
    end;
    if fresh then LidarDrawSeq := FrameSeq
    else if (FrameSeq - LidarDrawSeq) mod LIDAR_NOISE_EVERY = 0 then fresh := true;
    for i := 0 to n - 1 do begin
      if i <= MAX_RAY then begin
        if fresh then begin
          LidarRaw[i] := LidarCur[i];
          LidarNoisy[i] := AddNoise(LidarCur[i]);
        end;
        d := LidarNoisy[i];
      end else
        d := AddNoise(CleanRange(Mgetv(M, i, 0)));
      if i > 0 then s := s + ';';
      if d < 0 then s := s + '-1' else s := s + FmtReal(d);
    end;
  end;
  result := s;
end;


// ---------------------------------------------------------------------------------------------
// Actuators
// ---------------------------------------------------------------------------------------------

// Teleport labels of the reply just decoded (docs/protocol.md, "Teleport labels"): TpId (> 0, each
// applied once), TpTarget (a robot of the scene, e.g. Part3; absent: this script's robot), TpX, TpY,
// TpTh and optional TpZ. SimTwo's SetRobotPos (ODERobotsPublished.pas) calls TRobot.SetXYZTeta
// (ODERobots.pas 581-): every solid placed at the pose in its scene orientation, velocities zeroed.
// In SimTwo's RobotAtFactory scenes the parts are robots Part1..Part4 (RobotFactoryPro2022/scene.xml).
procedure ApplyTeleport;
var s, target: string;
    id, r: integer;
    x, y, z, th: double;
begin
  if not FindLabel('TpId', s) then exit;
  if not ParseIntStr(s, id) then begin
    LogMsg('teleport ignored: TpId is not an integer');
    exit;
  end;
  if (id <= 0) or (id = LastTpId) then exit;
  LastTpId := id;
  if not LabelReal('TpX', x) then begin
    LogMsg('teleport ' + IntToStr(id) + ' ignored: ' + RepError);
    exit;
  end;
  if not LabelReal('TpY', y) then begin
    LogMsg('teleport ' + IntToStr(id) + ' ignored: ' + RepError);
    exit;
  end;
  if not LabelReal('TpTh', th) then begin
    LogMsg('teleport ' + IntToStr(id) + ' ignored: ' + RepError);
    exit;
  end;
  z := 0;
  if FindLabel('TpZ', s) then begin
    if not ParseRealStr(s, z) then begin
      LogMsg('teleport ' + IntToStr(id) + ' ignored: TpZ is not a real number');
      exit;
    end;
  end;
  r := iRobot;
  target := ROBOT_ID;
  if FindLabel('TpTarget', s) then begin
    target := s;
    r := GetRobotIndex(target);
    if r < 0 then begin
      LogMsg('teleport ' + IntToStr(id) + ' ignored: no robot ' + target + ' in the scene');
      exit;
    end;
  end;
  SetRobotPos(r, x, y, z, th);
  NTeleports := NTeleports + 1;
  LogMsg('teleport ' + IntToStr(id) + ': ' + target + ' to x ' + FmtReal(x) + ' y ' + FmtReal(y)
         + ' z ' + FmtReal(z) + ' theta ' + FmtReal(th));
end;

// Wheel speed references for SimTwo's speed controller (enabled once, in Initialize) and the magnet
// x;y;theta of each part in turn (SimTwo's ground truth, field frame)
function PartsLine: string;
var i: integer;
begin
  result := '';
  for i := 0 to NParts - 1 do begin
    if i > 0 then result := result + ';';
    result := result + FmtReal(GetRobotX(iParts[i])) + ';' + FmtReal(GetRobotY(iParts[i])) + ';'
              + FmtReal(GetRobotTheta(iParts[i]));
  end;
end;

procedure ApplyCommand;
var wl, wr: double;
begin
  wl := (CmdV - CmdW * TRACK / 2) / WHEEL_RADIUS;     // rad/s, axis 0
  wr := (CmdV + CmdW * TRACK / 2) / WHEEL_RADIUS;     // rad/s, axis 1
  SetAxisSpeedRef(iRobot, iAxisLeft, wl);
  SetAxisSpeedRef(iRobot, iAxisRight, wr);
  MagnetApplied := 0;
  if iMagnet >= 0 then begin
    SetSensorVin(iRobot, iMagnet, CmdMagnet * MAGNET_VIN_ON);
    MagnetApplied := CmdMagnet;
  end;
end;


// ---------------------------------------------------------------------------------------------
// SimTwo's entry points
// ---------------------------------------------------------------------------------------------

// this procedure is called periodically (the script period, 40 ms)
procedure Control;
var txt, frame, lidar: string;
    encL, encR, contact, nRays: integer;
    accepted: boolean;
begin
  TimeMs := TimeMs + Round(ScriptPeriod() * 1000);

  // 1. sensors
  encL := GetAxisOdo(iRobot, iAxisLeft);
  encR := GetAxisOdo(iRobot, iAxisRight);
  OdoLeft := OdoLeft + encL;
  OdoRight := OdoRight + encR;
  contact := 0;
  if iContact >= 0 then begin
    if GetSensorVal(iRobot, iContact) > 0 then contact := 1;
  end;
  lidar := LidarLine(nRays);

  // 2. replies that arrived since the previous cycle (they answer earlier frames: the reply to
  //    this cycle's frame cannot arrive before Control returns)
  txt := ReadUDPData();
  DrainPacketList;

  // 3. the SensorFrame
  frame := LabelLine('RAF', IntToStr(PROTOCOL_VERSION))
         + LabelLine('Seq', IntToStr(FrameSeq))
         + LabelLine('Tms', IntToStr(TimeMs))
         + LabelLine('Enc1', IntToStr(encL))
         + LabelLine('Enc2', IntToStr(encR))
         + LabelLine('Odo1', IntToStr(OdoLeft))
         + LabelLine('Odo2', IntToStr(OdoRight))
         + LabelLine('X', FmtReal(GetRobotX(iRobot)))
         + LabelLine('Y', FmtReal(GetRobotY(iRobot)))
         + LabelLine('Theta', FmtReal(GetRobotTheta(iRobot)))
         + LabelLine('Contact', IntToStr(contact))
         + LabelLine('Magnet', IntToStr(MagnetApplied))
         + LabelLine('LidarN', IntToStr(nRays))
         + LabelLine('Lidar', lidar);
  if NParts > 0 then
    frame := frame + LabelLine('PartsN', IntToStr(NParts)) + LabelLine('Parts', PartsLine);
  WriteUDPData(CfgBridgeIP, CfgBridgePort, frame);
  NFrames := NFrames + 1;

  // 4. the reply
  accepted := false;
  if txt <> '' then begin
    if DecodeReply(txt) then begin
      ApplyTeleport;
      if SeqAcceptable(RepSeq) then begin
        CmdV := RepV;
        CmdW := RepW;
        CmdMagnet := RepMagnet;
        if RepSeq >= 0 then LastAppliedSeq := RepSeq;
        accepted := true;
        NAccepted := NAccepted + 1;
      end else begin
        NRejected := NRejected + 1;
        LogRepeated(NRejected, 'reply ignored: Seq ' + IntToStr(RepSeq) + ' is not newer than '
                    + IntToStr(LastAppliedSeq) + ' and at most ' + IntToStr(FrameSeq));
      end;
    end else begin
      NRejected := NRejected + 1;
      LogRepeated(NRejected, 'reply ignored: ' + RepError);
    end;
  end;

  // 5. no valid command for too long: stop the wheels (the magnet stays as it is)
  if accepted then begin
    LastValidMs := TimeMs;
    if TimedOut = 1 then LogMsg('commands again: wheels released');
    TimedOut := 0;
  end;
  if TimeMs - LastValidMs > CfgCommandTimeoutMs then begin
    if TimedOut = 0 then begin
      NTimeouts := NTimeouts + 1;
      LogMsg('no valid command for ' + IntToStr(TimeMs - LastValidMs) + ' ms: wheels stopped');
    end;
    TimedOut := 1;
    CmdV := 0;
    CmdW := 0;
  end;

  // 6. actuators
  ApplyCommand;

  if (FrameSeq > 0) and (FrameSeq mod STATUS_EVERY = 0) then
    LogMsg('frames ' + IntToStr(NFrames) + ', replies applied ' + IntToStr(NAccepted)
           + ', ignored ' + IntToStr(NRejected) + ', timeouts ' + IntToStr(NTimeouts));
  FrameSeq := FrameSeq + 1;
end;

// this procedure is called once when the script is started
procedure Initialize;
var i, j: integer;
    s: string;
begin
  CfgBridgeIP := BRIDGE_IP;
  CfgBridgePort := BRIDGE_PORT;
  CfgCommandTimeoutMs := COMMAND_TIMEOUT_MS;
  CfgLidarNoiseA := LIDAR_NOISE_A;
  CfgLidarNoiseB := LIDAR_NOISE_B;

  iRobot := GetRobotIndex(ROBOT_ID);
  if iRobot < 0 then begin
    LogMsg('robot ' + ROBOT_ID + ' not found in the scene: using robot 0');
    iRobot := 0;
  end;
  iAxisLeft := GetAxisIndex(iRobot, LEFT_AXIS_ID, 0);
  if iAxisLeft < 0 then begin
    LogMsg('axis ' + LEFT_AXIS_ID + ' not found: using axis 0');
    iAxisLeft := 0;
  end;
  iAxisRight := GetAxisIndex(iRobot, RIGHT_AXIS_ID, 0);
  if iAxisRight < 0 then begin
    LogMsg('axis ' + RIGHT_AXIS_ID + ' not found: using axis 1');
    iAxisRight := 1;
  end;
  iContact := GetSensorIndex(iRobot, CONTACT_ID);
  if iContact < 0 then LogMsg('sensor ' + CONTACT_ID + ' not found: Contact will be 0');
  iMagnet := GetSensorIndex(iRobot, MAGNET_ID);
  if iMagnet < 0 then LogMsg('sensor ' + MAGNET_ID + ' not found: the electromagnet cannot be switched');
  iLidar := GetSensorIndex(iRobot, LIDAR_ID);
  if iLidar < 0 then LogMsg('sensor ' + LIDAR_ID + ' not found: LidarN will be 0 (see simtwo/AGV_lidar.xml)');
  NParts := 0;
  if SEND_PARTS = 1 then begin
    for i := 1 to MAX_PARTS do begin
      j := GetRobotIndex(PART_PREFIX + IntToStr(i));
      if j < 0 then break;     // Part1..PartN: the first missing one ends the list
      iParts[NParts] := j;
      NParts := NParts + 1;
    end;
  end;

  FrameSeq := 0;
  TimeMs := 0;
  OdoLeft := 0;
  OdoRight := 0;
  CmdV := 0;
  CmdW := 0;
  CmdMagnet := 0;
  MagnetApplied := 0;
  LastAppliedSeq := -1;
  LastValidMs := 0;
  TimedOut := 0;
  NFrames := 0;
  NAccepted := 0;
  NRejected := 0;
  NTimeouts := 0;
  LastTpId := 0;
  NTeleports := 0;
  RCount := 0;
  LidarDrawSeq := 0;
  for i := 0 to MAX_RAY do begin
    LidarRaw[i] := -2;         // no range: the first sweep (SimTwo's zeros) is new
    LidarNoisy[i] := -1;
  end;

  // SimTwo's speed controller: gains and state set here, once (each call resets its integral)
  if SET_SPEED_GAINS = 1 then begin
    SetMotorControllerPars(iRobot, iAxisLeft, SPEED_KI, SPEED_KD, SPEED_KP, SPEED_KF);
    SetMotorControllerPars(iRobot, iAxisRight, SPEED_KI, SPEED_KD, SPEED_KP, SPEED_KF);
  end;
  SetMotorControllerState(iRobot, iAxisLeft, true);
  SetMotorControllerState(iRobot, iAxisRight, true);
  ApplyCommand;

  // whatever was queued before this start answers frames of an earlier run
  s := ReadUDPData();
  DrainPacketList;

  LogMsg('streaming to ' + BRIDGE_IP + ':' + IntToStr(BRIDGE_PORT)
         + ', command timeout ' + IntToStr(COMMAND_TIMEOUT_MS) + ' ms');
end;
