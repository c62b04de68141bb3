unit simtwo_api;

{ A stand-in for the part of SimTwo's script API that simtwo/control.pas uses, so that the script
  runs on Linux in SimTwo's own script engine (pscript/pscript_harness.pas registers these functions
  with PascalScript under SimTwo's declarations; tests/test_simtwo_pascalscript.py drives it).

  Names and parameter lists are SimTwo's (ODERobotsPublished, dynmatrix and the functions the script
  editor registers: WriteUDPData, ReadUDPData, ReadUDPPacket, GetUDPPacketCount, ScriptPeriod,
  GetTickCount, RandG, WriteLn). Behaviour copied from SimTwo's source where it matters:
  - ReadUDPData returns every datagram received since the previous call, concatenated, and clears
    that buffer; each datagram is also appended to a packet list that only ReadUDPPacket empties and
    GetUDPPacketCount counts (Params.pas 1273-1281 TFParams.UDPGenericReceive, Editor.pas 1438-1464).
  - Datagrams are sent from, and received on, one socket (SimTwo's UDPGeneric, port 9808): replies
    come back to the port the frames came from.
  - Datagrams arrive (are moved into those buffers) only between script runs: SimTwo's lNet socket
    delivers them through the GUI thread's event loop, the thread that runs the script.
  - GetSensorVal returns -1 when the sensor has no measure; GetSensorValues returns an n x 1 Matrix
    of the raw values (-1 for a ranger2d ray without a hit); Mgetv raises on an index out of range.

  Sensor values are a deterministic function of the cycle number, and every value returned and
  every actuator call is written to the record file (one line each) for the Python test to check.
  The harness waits for a datagram 'HARNESS-TICK' on its own UDP socket before each cycle (these
  never reach the script), so the test drives the cycles. Options are key=value arguments:
    record=FILE cycles=N bridge_ip=A bridge_port=N timeout_ms=N noise_z=F noise_a=F
    missing=ID,ID,... tick_timeout_ms=N
    sweep=N sweep_phase=P still=0|1   the LIDAR as SimTwo delivers it: a whole new sweep every N
                                      cycles from cycle P on, all zeros before (still=1: every sweep
                                      the same, a robot standing still); without sweep, new values
                                      every cycle (and odd ones in cycle 2) to exercise the sender }

{$mode delphi}{$H+}

interface

uses SysUtils, Classes, Math, Sockets, BaseUnix;

type
  { dynmatrix's Matrix. SimTwo (Windows) receives `const Mat: Matrix` by reference, as PascalScript's
    caller passes it; Free Pascal on x86_64 Linux would pass this 16-byte record in registers, so the
    stand-in declares those parameters constref: the same by-reference passing, spelled for this ABI. }
  Matrix = record
    data: array of double;
    rows: LongWord;
    cols: LongWord;
  end;

{ ---- SimTwo's script API ---- }
function GetRobotIndex(ID: string): integer;
function GetAxisIndex(R: integer; ID: string; i: integer): integer;
function GetSensorIndex(R: integer; ID: string): integer;
function GetAxisOdo(R, i: integer): integer;
function GetRobotX(R: integer): double;
function GetRobotY(R: integer): double;
function GetRobotTheta(R: integer): double;
function GetSensorVal(R, i: integer): double;
function GetSensorValues(R, i: integer): Matrix;
procedure SetSensorVin(R, i: integer; Vin: byte);
procedure SetAxisSpeedRef(R, i: integer; aSpeed: double);
procedure SetMotorControllerState(R, i: integer; newState: boolean);
procedure SetMotorControllerPars(R, i: integer; nKi, nKd, nKp, nKf: double);
procedure SetRobotPos(R: integer; x, y, z, teta: double);
function MNumRows(constref Mat: Matrix): Longword;
function MNumCols(constref Mat: Matrix): Longword;
function Mgetv(constref Mat: Matrix; r, c: Longword): double;
function ScriptPeriod: double;
function GetTickCount: LongWord;
function RandG(Mean, StdDev: Extended): Extended;
procedure WriteLn(S: string);
procedure WriteUDPData(ToIP: string; ToPort: integer; s: string);
function ReadUDPData: string;
function ReadUDPPacket: string;
function GetUDPPacketCount: integer;

{ ---- the harness side ---- }
var
  HCycle: integer = -1;       // the cycle being run (-1 during Initialize)

procedure HarnessStart;
procedure HarnessWaitTick;
procedure HarnessRec(const line: string);
procedure HarnessFinish;
function HarnessHas(const key: string): boolean;
function HarnessOpt(const key, default: string): string;
function HarnessReal(v: double): string;
function HarnessOptReal(const key: string; default: double): double;

implementation

const
  ROBOT_ROWS: array[0..4] of string = ('AGV', 'Part1', 'Part2', 'Part3', 'Part4');  // as RobotFactoryPro2022/scene.xml
  SENSOR_IDS: array[0..8] of string =
    ('Line0', 'Line1', 'Line2', 'Line3', 'Line4', 'solenoid1', 'MicroSwitch', 'RFID', 'ranger2d');
  AXIS_IDS: array[0..1] of string = ('LeftAxis', 'RightAxis');
  N_RAYS = 360;

var
  HOpts: TStringList;
  HMissing: TStringList;
  HFS: TFormatSettings;        // '.' decimal point for the record, whatever the script's locale
  HRec: TextFile;
  HRecOpen: boolean = false;
  HSock: cint = -1;
  HPort: integer;
  HTicks: integer = 0;
  HNoiseZ: double = 0;
  HTickTimeoutMs: QWord = 20000;
  HSweep: integer = 0;
  HSweepPhase: integer = 0;
  HStill: boolean = false;
  HGenData: string = '';
  HGenPackets: TStringList;
  HBuf: array[0..65535] of byte;

{ ---- helpers ---- }

function HarnessReal(v: double): string;
begin
  result := Format('%.17g', [v], HFS);
end;

procedure HarnessRec(const line: string);
begin
  if HRecOpen then System.WriteLn(HRec, line);
end;

procedure Fail(const msg: string);
begin
  HarnessRec('ERROR ' + msg);
  raise Exception.Create(msg);
end;

function HarnessHas(const key: string): boolean;
begin
  result := HOpts.IndexOfName(key) >= 0;
end;

function HarnessOpt(const key, default: string): string;
begin
  if HarnessHas(key) then result := HOpts.Values[key] else result := default;
end;

function HarnessOptReal(const key: string; default: double): double;
begin
  if HarnessHas(key) then result := StrToFloat(HOpts.Values[key], HFS) else result := default;
end;

function Present(const id: string): boolean;
begin
  result := HMissing.IndexOf(id) < 0;
end;

procedure CheckRobot(R: integer; const fn: string);
begin
  if R <> 0 then Fail(Format('%s: robot index %d does not exist', [fn, R]));
end;

procedure CheckSensor(R, i: integer; const fn: string);
begin
  CheckRobot(R, fn);
  if (i < 0) or (i > High(SENSOR_IDS)) or (not Present(SENSOR_IDS[i])) then
    Fail(Format('%s: sensor index %d does not exist', [fn, i]));
end;

procedure CheckAxis(R, i: integer; const fn: string);
begin
  CheckRobot(R, fn);
  if (i < 0) or (i > High(AXIS_IDS)) then Fail(Format('%s: axis index %d does not exist', [fn, i]));
end;

{ ---- UDP: SimTwo's receive side is an event that appends to two buffers ---- }

procedure Pump;
var n: ssize_t;
    from: TInetSockAddr;
    fromlen: TSockLen;
    s: string;
begin
  repeat
    fromlen := SizeOf(from);
    n := fpRecvFrom(HSock, @HBuf[0], SizeOf(HBuf), MSG_DONTWAIT, @from, @fromlen);
    if n >= 0 then begin
      SetString(s, PAnsiChar(@HBuf[0]), n);
      if s = 'HARNESS-TICK' then
        Inc(HTicks)
      else begin
        HGenData := HGenData + s;
        HGenPackets.Add(s);
        HarnessRec(Format('RECV %d %d', [HCycle, n]));
      end;
    end;
  until n < 0;
end;

procedure WriteUDPData(ToIP: string; ToPort: integer; s: string);
var addr: TInetSockAddr;
    n: ssize_t;
begin
  FillChar(addr, SizeOf(addr), 0);
  addr.sin_family := AF_INET;
  addr.sin_port := htons(ToPort);
  addr.sin_addr := StrToNetAddr(ToIP);
  if s = '' then n := fpSendTo(HSock, nil, 0, 0, @addr, SizeOf(addr))
  else n := fpSendTo(HSock, @s[1], Length(s), 0, @addr, SizeOf(addr));
  HarnessRec(Format('SEND %d %s %d %d %d', [HCycle, ToIP, ToPort, Length(s), n]));
end;

function ReadUDPData: string;
begin
  result := HGenData;
  HGenData := '';
  if result <> '' then HarnessRec(Format('READ %d %d', [HCycle, Length(result)]));
end;

function ReadUDPPacket: string;
begin
  result := '';
  if HGenPackets.Count > 0 then begin
    result := HGenPackets[0];
    HGenPackets.Delete(0);
  end;
end;

function GetUDPPacketCount: integer;
begin
  result := HGenPackets.Count;
end;

{ ---- scripted sensors (deterministic in the cycle number k) ---- }

function GetRobotIndex(ID: string): integer;
var i: integer;
begin
  result := -1;
  for i := 0 to High(ROBOT_ROWS) do
    if (ID = ROBOT_ROWS[i]) and Present(ID) then result := i;
  HarnessRec(Format('GET %d RobotIndex %s %d', [HCycle, ID, result]));
end;

function GetAxisIndex(R: integer; ID: string; i: integer): integer;
var k: integer;
begin
  CheckRobot(R, 'GetAxisIndex');
  result := -1;
  if (i = 0) and Present(ID) then
    for k := 0 to High(AXIS_IDS) do
      if AXIS_IDS[k] = ID then result := k;
  HarnessRec(Format('GET %d AxisIndex %s %d', [HCycle, ID, result]));
end;

function GetSensorIndex(R: integer; ID: string): integer;
var k: integer;
begin
  CheckRobot(R, 'GetSensorIndex');
  result := -1;
  if Present(ID) then
    for k := 0 to High(SENSOR_IDS) do
      if SENSOR_IDS[k] = ID then result := k;
  HarnessRec(Format('GET %d SensorIndex %s %d', [HCycle, ID, result]));
end;

function GetAxisOdo(R, i: integer): integer;
var k: integer;
begin
  CheckAxis(R, i, 'GetAxisOdo');
  k := HCycle;
  if i = 0 then result := ((k * 7) mod 23) - 9
  else result := 12 - ((k * 5) mod 19);
  HarnessRec(Format('GET %d AxisOdo %d %d', [HCycle, i, result]));
end;

// the parts (robots 1..4): a pose per robot and cycle, recorded as PartX/PartY/PartTheta R value
function PartValue(R: integer; const what: string): double;
begin
  if (R < 1) or (R > High(ROBOT_ROWS)) then Fail(Format('Get%s: robot index %d does not exist', [what, R]));
  if what = 'X' then result := 0.1 * R - 0.00731 * HCycle
  else if what = 'Y' then result := -0.45 + 0.2 * R + 1.5e-6 * HCycle
  else result := 0.25 * R - 3.0 + 0.011 * HCycle;
  HarnessRec(Format('GET %d Part%s %d %s', [HCycle, what, R, HarnessReal(result)]));
end;

function GetRobotX(R: integer): double;
begin
  if R > 0 then begin
    result := PartValue(R, 'X');
    exit;
  end;
  CheckRobot(R, 'GetRobotX');
  result := -0.725 + 0.0123456789 * HCycle;
  HarnessRec(Format('GET %d RobotX %s', [HCycle, HarnessReal(result)]));
end;

function GetRobotY(R: integer): double;
var k: integer;
begin
  if R > 0 then begin
    result := PartValue(R, 'Y');
    exit;
  end;
  CheckRobot(R, 'GetRobotY');
  k := HCycle;
  if k mod 10 = 3 then result := 2.5e-6 * k
  else if k mod 10 = 7 then result := -1.5e-5
  else if k mod 10 = 9 then result := 1234567.0 + k
  else result := 0.4 * sin(0.37 * k);
  HarnessRec(Format('GET %d RobotY %s', [HCycle, HarnessReal(result)]));
end;

function GetRobotTheta(R: integer): double;
var a: double;
begin
  if R > 0 then begin
    result := PartValue(R, 'Theta');
    exit;
  end;
  CheckRobot(R, 'GetRobotTheta');
  a := 0.3 * HCycle - 3.0;
  while a > pi do a := a - 2 * pi;
  while a <= -pi do a := a + 2 * pi;
  result := a;
  HarnessRec(Format('GET %d RobotTheta %s', [HCycle, HarnessReal(result)]));
end;

function GetSensorVal(R, i: integer): double;
begin
  CheckSensor(R, i, 'GetSensorVal');
  result := -1;                                  // SimTwo: -1 when there is no measure
  if (SENSOR_IDS[i] = 'MicroSwitch') and (HCycle mod 5 = 2) then result := 0.004;
  HarnessRec(Format('GET %d SensorVal %d %s', [HCycle, i, HarnessReal(result)]));
end;

function RayValue(i, k: integer): double;
begin
  if (i + k) mod 11 = 0 then result := -1
  else result := 0.05 + ((i * 37 + k * 13) mod 5900) / 1000 + i * 1e-7;
  if k = 2 then begin                            // values the script must clean or format
    if i = 5 then result := NaN;                 // not a number: sent as no return
    if i = 6 then result := -0.9987;             // SimTwo noise on a no-return -1
    if i = 7 then result := 1e-6;                // tiny: exponent format
    if i = 8 then result := 0.0;
  end;
end;

function GetSensorValues(R, i: integer): Matrix;
var j, n: integer;
    s: string;
begin
  CheckSensor(R, i, 'GetSensorValues');
  n := 1;
  if SENSOR_IDS[i] = 'ranger2d' then n := N_RAYS;
  SetLength(result.data, n);
  result.rows := n;
  result.cols := 1;
  s := '';
  for j := 0 to n - 1 do begin
    if SENSOR_IDS[i] <> 'ranger2d' then result.data[j] := -1
    else if HSweep <= 0 then result.data[j] := RayValue(j, HCycle)
    else if HCycle < HSweepPhase then result.data[j] := 0       // SimTwo: 0 before the first sweep
    else if HStill then result.data[j] := RayValue(j, 100)
    else result.data[j] := RayValue(j, 100 + (HCycle - HSweepPhase) div HSweep);
    if j > 0 then s := s + ';';
    s := s + HarnessReal(result.data[j]);
  end;
  HarnessRec(Format('GET %d SensorValues %d %d %s', [HCycle, i, n, s]));
end;

function MNumRows(constref Mat: Matrix): Longword;
begin
  result := Mat.rows;
end;

function MNumCols(constref Mat: Matrix): Longword;
begin
  result := Mat.cols;
end;

function Mgetv(constref Mat: Matrix; r, c: Longword): double;
begin
  if (r >= Mat.rows) or (c >= Mat.cols) then
    Fail(Format('Mgetv: (%d, %d) outside a %d x %d matrix', [r, c, Mat.rows, Mat.cols]));
  result := Mat.data[r * Mat.cols + c];
end;

function ScriptPeriod: double;
begin
  result := 0.04;
end;

function GetTickCount: LongWord;
begin
  result := LongWord(GetTickCount64);
end;

function RandG(Mean, StdDev: Extended): Extended;
begin
  result := Mean + StdDev * HNoiseZ;             // deterministic "noise": the test knows z
  HarnessRec(Format('DRAW %d', [HCycle]));
end;

procedure WriteLn(S: string);
begin
  HarnessRec(Format('LOG %d %s', [HCycle, S]));
end;

{ ---- actuators: recorded ---- }

procedure SetSensorVin(R, i: integer; Vin: byte);
begin
  CheckSensor(R, i, 'SetSensorVin');
  HarnessRec(Format('SET %d SensorVin %d %d', [HCycle, i, Vin]));
end;

procedure SetAxisSpeedRef(R, i: integer; aSpeed: double);
begin
  CheckAxis(R, i, 'SetAxisSpeedRef');
  HarnessRec(Format('SET %d AxisSpeedRef %d %s', [HCycle, i, HarnessReal(aSpeed)]));
end;

procedure SetRobotPos(R: integer; x, y, z, teta: double);
begin
  if (R < 0) or (R > High(ROBOT_ROWS)) then Fail(Format('SetRobotPos: robot index %d does not exist', [R]));
  HarnessRec(Format('SET %d RobotPos %d %s %s %s %s', [HCycle, R, HarnessReal(x), HarnessReal(y), HarnessReal(z),
                                                       HarnessReal(teta)]));
end;

procedure SetMotorControllerState(R, i: integer; newState: boolean);
begin
  CheckAxis(R, i, 'SetMotorControllerState');
  HarnessRec(Format('SET %d MotorControllerState %d %d', [HCycle, i, Ord(newState)]));
end;

procedure SetMotorControllerPars(R, i: integer; nKi, nKd, nKp, nKf: double);
begin
  CheckAxis(R, i, 'SetMotorControllerPars');
  HarnessRec(Format('SET %d MotorControllerPars %d %s %s %s %s',
    [HCycle, i, HarnessReal(nKi), HarnessReal(nKd), HarnessReal(nKp), HarnessReal(nKf)]));
end;

{ ---- harness life cycle ---- }

procedure HarnessStart;
var i: integer;
    addr: TInetSockAddr;
    len: TSockLen;
begin
  HFS := DefaultFormatSettings;
  HFS.DecimalSeparator := '.';
  HOpts := TStringList.Create;
  for i := 1 to ParamCount do HOpts.Add(ParamStr(i));
  HMissing := TStringList.Create;
  HMissing.Delimiter := ',';
  HMissing.StrictDelimiter := true;
  HMissing.DelimitedText := HarnessOpt('missing', '');
  HGenPackets := TStringList.Create;
  HNoiseZ := HarnessOptReal('noise_z', 0);
  HTickTimeoutMs := StrToInt(HarnessOpt('tick_timeout_ms', '20000'));
  HSweep := StrToInt(HarnessOpt('sweep', '0'));
  HSweepPhase := StrToInt(HarnessOpt('sweep_phase', '0'));
  HStill := HarnessOpt('still', '0') = '1';

  AssignFile(HRec, HarnessOpt('record', 'record.txt'));
  Rewrite(HRec);
  HRecOpen := true;


  HSock := fpSocket(AF_INET, SOCK_DGRAM, 0);
  if HSock < 0 then Fail('socket() failed');
  FillChar(addr, SizeOf(addr), 0);
  addr.sin_family := AF_INET;
  addr.sin_port := htons(0);
  addr.sin_addr := StrToNetAddr('127.0.0.1');
  if fpBind(HSock, @addr, SizeOf(addr)) <> 0 then Fail('bind() failed');
  len := SizeOf(addr);
  fpGetSockName(HSock, @addr, @len);
  HPort := ntohs(addr.sin_port);
  HarnessRec(Format('PORT %d', [HPort]));
  System.WriteLn('PORT ', HPort);
  Flush(Output);
end;

procedure HarnessWaitTick;
var t0: QWord;
    pfd: TPollFd;
begin
  t0 := GetTickCount64;
  Pump;
  while HTicks = 0 do begin
    if GetTickCount64 - t0 > HTickTimeoutMs then Fail('no HARNESS-TICK from the test');
    pfd.fd := HSock;
    pfd.events := POLLIN;
    pfd.revents := 0;
    fpPoll(@pfd, 1, 50);
    Pump;
  end;
  Dec(HTicks);
end;

procedure HarnessFinish;
begin
  HarnessRec('DONE');
  if HRecOpen then CloseFile(HRec);
  HRecOpen := false;
  if HSock >= 0 then CloseSocket(HSock);
end;

end.
