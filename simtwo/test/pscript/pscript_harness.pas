program pscript_harness;

{ SimTwo's script engine on Linux: RemObjects PascalScript (built from Debian's lazarus-src-2.2), set up
  as SimTwo's script editor sets it up (github.com/P33a/SimTwo, Editor.pas / Editor.lfm):
  - a TPSScriptDebugger with CompilerOptions [icBooleanShortCircuit], UsePreProcessor, MainFileName
    'unnamed' (Editor.lfm 1057-1080);
  - the same plugins in the same order (simtwo_plugins.pas) and, in OnCompile, the editor's own
    functions, types and variables in the order of TFEditor.PSScript_Compile (Editor.pas 939-1054);
  - the script text built as TFEditor.Compile builds it (Editor.pas 406): the header memo
    (SynMemoHeader, Editor.lfm 768-771) + CR LF + the script + CR LF CR LF + 'begin Control; end.'
  - run as TFEditor.RunOnce runs it (Editor.pas 311-395): FPU exceptions masked, Initialize through
    ExecuteFunction on the first cycle, then Execute (the main block calls Control) every cycle.
  SimTwo forces '.' as the decimal separator at start-up (Viewer.pas 4393); so does this harness.

  Usage:
    pscript_harness compile SCRIPT           compile only; prints PascalScript's messages;
                                             exit 0 when it compiles, 1 when it does not
    pscript_harness run SCRIPT key=value...  compile, then run against the stand-in API of
                                             simtwo_api.pas (options: see there); exit 1 when the
                                             script does not compile, 3 on a run-time error
  Compile messages are printed as SimTwo's Errors tab lists them (MessageToString), each followed by
  the line in SCRIPT itself (SimTwo's line numbers count the header). }

{$mode delphi}{$H+}

uses
  SysUtils, Classes, Math, uPSComponent, uPSCompiler, uPSRuntime, uPSUtils, uPSDebugger,
  simtwo_plugins, simtwo_api;

const
  CRLF = #13#10;
  // SynMemoHeader.Text: its two lines, each ended by the line break (Editor.lfm 768-771)
  HEADER = 'const MaxDim  = 8;' + CRLF + 'const k = MaxDim-1;' + CRLF;
  HEADER_LINES = 3;   // the header's two lines and the CR LF TFEditor.Compile adds after it

type
  THost = class(TComponent)
  public
    ProgTime: double;
    HUDStrings: TStringList;
    UDPDataRead: TMemoryStream;
    procedure OnCompile(Sender: TPSScript);
    procedure OnExecute(Sender: TPSScript);
  end;

{ ---- the editor's own functions (TFEditor.PSScript_Compile): stand-ins where the harness needs them ---- }

function PSFormat(const sFormat: string; const Args: array of const): string;
begin
  result := SysUtils.Format(sFormat, Args);
end;

function ExpD(X: double): double;
begin
  result := System.Exp(X);
end;

function SqrD(X: double): double;
begin
  result := X * X;
end;

function LnD(X: double): double;
begin
  result := System.Ln(X);
end;

function ATan2D(y, x: double): double;
begin
  result := Math.ArcTan2(y, x);
end;

function NowD: double;
begin
  result := SysUtils.Now;
end;

{ RandG(Mean, StdDev: Extended): Extended. SimTwo is a Windows build, where Free Pascal's Extended is
  a Double on x86_64; on Linux x86_64 it is the 80-bit type, which PascalScript's native call passes
  differently from Free Pascal. Called through PascalScript's stack instead (no native call), with the
  same declaration. }
function RandG_PS(Caller: TPSExec; p: TPSExternalProcRec; Global, Stack: TPSStack): Boolean;
begin
  Stack.SetReal(-1, RandG(Stack.GetReal(-2), Stack.GetReal(-3)));
  result := true;
end;

procedure FnStack(Sender: TPSScript; Proc: TPSProcPtr; const Decl: string);
var p: TPSRegProc;
begin
  p := Sender.Comp.AddDelphiFunction(Decl);
  if p = nil then raise Exception.Create('PascalScript refused the declaration ' + Decl);
  Sender.Exec.RegisterFunctionName(p.Name, Proc, nil, nil);
end;

{ Registers Decl as SimTwo's editor does (Sender.AddFunction: the compiler's declaration and, when the
  harness has a stand-in, the run-time function); without a stand-in only the declaration. }
procedure Fn(Sender: TPSScript; Ptr: Pointer; const Decl: string);
var ok: boolean;
begin
  if Ptr <> nil then ok := Sender.AddFunction(Ptr, Decl)
  else ok := Sender.Comp.AddDelphiFunction(Decl) <> nil;
  if not ok then raise Exception.Create('PascalScript refused the declaration ' + Decl);
end;

procedure THost.OnCompile(Sender: TPSScript);
begin
  Fn(Sender, nil, 'function arcsin(x: Extended): Extended');
  Fn(Sender, nil, 'function arccos(x: Extended): Extended');
  Fn(Sender, nil, 'function tan(x: Extended): Extended');
  Fn(Sender, @ATan2D, 'function ATan2(y,x: double): double');
  Fn(Sender, nil, 'function ACos2(y,x: double): double');
  Fn(Sender, nil, 'function ASin2(y,x: double): double');
  Fn(Sender, nil, 'function Power(const Base, Exponent: Extended): Extended');
  Fn(Sender, nil, 'function Log10(const X: Extended): Extended');
  Fn(Sender, nil, 'function LogN(const Base, X: Extended): Extended');
  Fn(Sender, @SqrD, 'function Sqr(X: double): double');
  Fn(Sender, @ExpD, 'function Exp(X: double): double');
  Fn(Sender, @LnD, 'function Ln(X: double): double');
  Fn(Sender, nil, 'function FloatAsInteger(X: single): integer');
  Fn(Sender, nil, 'function IntegerAsFloat(X: integer): single');
  Fn(Sender, nil, 'function DiffAngle(a1,a2: double): double;');
  Fn(Sender, nil, 'function Dist(x,y: double): double');
  Fn(Sender, nil, 'function Sign(a: double): double');
  Fn(Sender, nil, 'function Sat(a,limit: double): double');
  Fn(Sender, nil, 'function NormalizeAngle(ang: double): double');
  Fn(Sender, nil, 'function TranslateAndRotate(var rx,ry: double; px,py,tx,ty,teta: double): double');
  Fn(Sender, nil, 'function RotateAndTranslate(var rx,ry: double; px,py,tx,ty,teta: double): double');
  Fn(Sender, nil, 'function RotateAroundPoint(var rx,ry: double; px,py,cx,cy,teta: double): double');
  FnStack(Sender, RandG_PS, 'function RandG(Mean, StdDev: Extended): Extended;');
  Fn(Sender, nil, 'function random01: double;');
  Fn(Sender, nil, 'procedure Randomize;');
  Fn(Sender, nil, 'function BiLinInterp(Surf: matrix; xmin, xmax, ymin, ymax, x,y: double): double;');
  Fn(Sender, nil, 'function IntToHex(Value: integer; Digits: Integer): string;');
  Fn(Sender, @WriteLn, 'procedure WriteLn(S: string)');
  Fn(Sender, @PSFormat, 'function Format(const sFormat: string; const Args: array of const): string;');
  Fn(Sender, nil, 'function ReadComPort: string;');
  Fn(Sender, nil, 'procedure WriteComPort(s: string);');
  Fn(Sender, @ReadUDPData, 'function ReadUDPData: string;');
  Fn(Sender, @WriteUDPData, 'procedure WriteUDPData(ToIP: string; ToPort: integer; s: string);');
  Fn(Sender, @ReadUDPPacket, 'function ReadUDPPacket: string;');
  Fn(Sender, @GetUDPPacketCount, 'function GetUDPPacketCount: integer;');
  Fn(Sender, nil, 'procedure SetRCValue(r, c: integer; s: string);');
  Fn(Sender, nil, 'function GetRCValue(r, c: integer): double;');
  Fn(Sender, nil, 'function GetRCText(r, c: integer): string;');
  Fn(Sender, nil, 'function RCButtonPressed(r, c: integer): boolean;');
  Fn(Sender, nil, 'function RangeToMatrix(r, c, rows, cols: integer): Matrix;');
  Fn(Sender, nil, 'procedure MatrixToRange(r, c: integer; const M: Matrix);');
  Fn(Sender, nil, 'procedure MatrixToRangeF(r, c: integer; const M: Matrix; FormatString: string);');
  Fn(Sender, nil, 'procedure ClearButtons;');
  Fn(Sender, nil, 'procedure RefreshSheets;');
  Fn(Sender, nil, 'procedure CloseSimTwo;');
  Fn(Sender, @ScriptPeriod, 'function ScriptPeriod: double;');
  Fn(Sender, @NowD, 'function Now: double;');
  Fn(Sender, @GetTickCount, 'function GetTickCount: LongWord;');
  Fn(Sender, nil, 'procedure SetRCBackColor(r, c: integer; newColor: TColor);');
  Fn(Sender, nil, 'function RGBToColor(R, G, B: Byte): TColor; ');
  Fn(Sender, nil, 'procedure Test(var B: double);');
  Sender.Comp.AddTypeS('TUDPBuffer', 'record data: array[0..1499] of byte; MessSize: integer; ReadDisp: integer;  end').ExportName := true;
  Fn(Sender, nil, 'procedure ClearUDPBuffer(var Buf: TUDPBuffer);');
  Fn(Sender, nil, 'procedure NetBufferSeek(var Buf: TUDPBuffer; disp: integer);');
  Fn(Sender, nil, 'function NetStringBuffer(var Buf: TUDPBuffer): string;');
  Fn(Sender, nil, 'procedure NetPutByte(var Buf: TUDPBuffer; value: byte);');
  Fn(Sender, nil, 'procedure NetPutWord(var Buf: TUDPBuffer; value: word);');
  Fn(Sender, nil, 'procedure NetPutShort(var Buf: TUDPBuffer; value: SmallInt);');
  Fn(Sender, nil, 'procedure NetPutInt(var Buf: TUDPBuffer; value: integer);');
  Fn(Sender, nil, 'procedure NetPutFloat(var Buf: TUDPBuffer; value: single);');
  Fn(Sender, nil, 'procedure NetPutString(var Buf: TUDPBuffer; str: string);');
  Fn(Sender, nil, 'procedure NetPutAngle(var Buf: TUDPBuffer; value: double);');
  Fn(Sender, nil, 'function NetPeekByte(var Buf: TUDPBuffer): byte;');
  Fn(Sender, nil, 'function NetGetByte(var Buf: TUDPBuffer): byte;');
  Fn(Sender, nil, 'function NetGetWord(var Buf: TUDPBuffer): word;');
  Fn(Sender, nil, 'function NetGetShort(var Buf: TUDPBuffer): SmallInt;');
  Fn(Sender, nil, 'function NetGetInt(var Buf: TUDPBuffer): integer;');
  Fn(Sender, nil, 'function NetGetFloat(var Buf: TUDPBuffer): single;');
  Fn(Sender, nil, 'function NetGetString(var Buf: TUDPBuffer): string;');
  Fn(Sender, nil, 'function NetGetAngle(var Buf: TUDPBuffer): double;');
  Fn(Sender, nil, 'function getModbusCoil(bit_addr: integer): boolean;');
  Fn(Sender, nil, 'function getModbusInput(bit_addr: integer): boolean;');
  Fn(Sender, nil, 'procedure setModbusCoil(bit_addr: integer; new_state: boolean);');
  Fn(Sender, nil, 'procedure setModbusInput(bit_addr: integer; new_state: boolean);');
  Sender.Comp.AddTypeS('TGLPixel32', 'record r, g, b, a: byte; end;').ExportName := true;
  Fn(Sender, nil, 'function GetCameraPixel(X, Y: integer): TRGBAColor;');
  Sender.AddRegisteredPTRVariable('Time', 'Double');
  Sender.AddRegisteredPTRVariable('UDPDataRead', 'TMemoryStream');
  Sender.AddRegisteredPTRVariable('HUDStrings', 'TStringList');
  Sender.AddRegisteredPTRVariable('CamBitmap', 'TBitmap');
  Sender.AddRegisteredPTRVariable('RandSeed', 'LongInt');
end;

procedure THost.OnExecute(Sender: TPSScript);
var t: TPSTypeRec;
begin
  // TFEditor.PSScript_Execute (Editor.pas 1101-1121); CamBitmap stays unset: no TBitmap at run time here
  Sender.SetPointerToData('Time', @ProgTime, Sender.FindBaseType(btDouble));
  t := Sender.FindNamedType('TMemoryStream');
  if t <> nil then Sender.SetPointerToData('UDPDataRead', @UDPDataRead, t);
  t := Sender.FindNamedType('TStringList');
  if t <> nil then Sender.SetPointerToData('HUDStrings', @HUDStrings, t);
  Sender.SetPointerToData('RandSeed', @RandSeed, Sender.FindBaseType(btS32));
end;

{ ---- building and compiling ---- }

var
  Host: THost;
  PS: TPSScriptDebugger;
  ScriptFile, Mode: string;
  HK, HN: integer;
  HT0: QWord;
  Mask: TFPUExceptionMask;

function CreateEngine: TPSScriptDebugger;
begin
  result := TPSScriptDebugger.Create(Host);
  result.CompilerOptions := [icBooleanShortCircuit];
  result.UsePreProcessor := true;
  result.MainFileName := 'unnamed';
  result.OnCompile := Host.OnCompile;
  result.OnExecute := Host.OnExecute;
  AddSimTwoPlugins(result, Host);
end;

function CompileScript(const path: string): boolean;
var src: TStringList;
    i, errors: integer;
    m: TPSPascalCompilerMessage;
    msgs: TStringList;
    rows, cols: array of integer;
begin
  src := TStringList.Create;
  try
    src.LoadFromFile(path);
    // TFEditor.Compile: SynMemoHeader.Text + crlf + SynEditST.text + crlf + crlf + 'begin Control; end.'
    src.LineBreak := CRLF;
    PS.Script.Text := HEADER + CRLF + src.Text + CRLF + CRLF + 'begin Control; end.';
  finally
    src.Free;
  end;
  // PascalScript's preprocessor (SimTwo: UsePreProcessor) miscounts rows: lines holding only a //
  // comment are not counted. A second compile without it, only for the positions, gives the true
  // line of each message in SCRIPT.
  PS.UsePreProcessor := false;
  PS.SuppressLoadData := true;
  PS.Comp.Clear;
  PS.Compile;
  SetLength(rows, PS.CompilerMessageCount);
  SetLength(cols, PS.CompilerMessageCount);
  msgs := TStringList.Create;
  for i := 0 to PS.CompilerMessageCount - 1 do begin
    msgs.Add(PS.CompilerMessages[i].ShortMessageToString);
    rows[i] := PS.CompilerMessages[i].Row;
    cols[i] := PS.CompilerMessages[i].Col;
  end;
  // SimTwo's compile. TPSScript.Compile also loads the byte code into the run-time, which needs every
  // routine the script calls; SimTwo has them all, the stand-in only those control.pas uses. Compiling
  // alone (SuppressLoadData) is SimTwo's compile; 'run' loads too and says what the stand-in lacks.
  PS.UsePreProcessor := true;
  PS.SuppressLoadData := (Mode = 'compile');
  PS.Comp.Clear;
  result := PS.Compile;
  System.WriteLn('Compile Messages:', PS.CompilerMessageCount);
  errors := 0;
  for i := 0 to PS.CompilerMessageCount - 1 do begin
    m := PS.CompilerMessages[i];
    if m is TPSPascalCompilerError then Inc(errors);
    System.WriteLn(m.MessageToString);
    if (i < msgs.Count) and (msgs[i] = m.ShortMessageToString) then begin
      if rows[i] > HEADER_LINES then
        System.WriteLn(Format('  (%s line %d, column %d)', [ExtractFileName(path), rows[i] - HEADER_LINES, cols[i]]))
      else
        System.WriteLn(Format('  (SimTwo''s header, line %d)', [rows[i]]));
    end;
  end;
  msgs.Free;
  if result then System.WriteLn('Compile OK')
  else if errors = 0 then  // compiled, but the byte code did not load
    System.WriteLn('Compiled, but not loaded (the stand-in lacks a routine or type it uses): ',
                   PS.ExecErrorToString)
  else System.WriteLn('Compile FAILED');
  Flush(Output);
end;

{ ---- running ---- }

// A global variable of the script (nil: none of that name), found as SimTwo's variable inspector
// finds it (Editor.pas 356-358)
function GVar(const name: string): PIFVariant;
var i: integer;
begin
  result := nil;
  for i := 0 to PS.Exec.GlobalVarNames.Count - 1 do
    if SameText(PS.Exec.GlobalVarNames[i], name) then result := PS.Exec.GetGlobalVar(i);
end;

// control.pas's settings in effect (those a script has: a test's script may have none)
procedure RecordSettings;
var v: PIFVariant;
begin
  v := GVar('CfgBridgeIP');
  if v <> nil then HarnessRec('CFG BridgeIP ' + VGetString(v));
  v := GVar('CfgBridgePort');
  if v <> nil then HarnessRec('CFG BridgePort ' + IntToStr(VGetInt(v)));
  v := GVar('CfgCommandTimeoutMs');
  if v <> nil then HarnessRec('CFG CommandTimeoutMs ' + IntToStr(VGetInt(v)));
  v := GVar('CfgLidarNoiseA');
  if v <> nil then HarnessRec('CFG LidarNoiseA ' + HarnessReal(VGetReal(v)));
  v := GVar('CfgLidarNoiseB');
  if v <> nil then HarnessRec('CFG LidarNoiseB ' + HarnessReal(VGetReal(v)));
end;

// The test's settings, as a user would edit the constants at the top of control.pas
procedure ApplyOptions;
var v: PIFVariant;
begin
  v := GVar('CfgBridgeIP');
  if (v <> nil) and HarnessHas('bridge_ip') then VSetString(v, HarnessOpt('bridge_ip', ''));
  v := GVar('CfgBridgePort');
  if (v <> nil) and HarnessHas('bridge_port') then VSetInt(v, StrToInt(HarnessOpt('bridge_port', '')));
  v := GVar('CfgCommandTimeoutMs');
  if (v <> nil) and HarnessHas('timeout_ms') then VSetInt(v, StrToInt(HarnessOpt('timeout_ms', '')));
  v := GVar('CfgLidarNoiseA');
  if (v <> nil) and HarnessHas('noise_a') then VSetReal(v, HarnessOptReal('noise_a', 0));
end;

procedure MaskLikeSimTwo;
begin
  // TFEditor.RunOnce (Editor.pas 325-326)
  Mask := GetExceptionMask;
  SetExceptionMask([exInvalidOp, exDenormalized, exZeroDivide, exOverflow, exUnderflow, exPrecision]);
end;

procedure Unmask;
begin
  ClearExceptions(false);
  SetExceptionMask(Mask);
end;

procedure RunError(const what: string);
begin
  HarnessRec(Format('EXCEPTION %d %s', [HCycle, what]));
  System.WriteLn('Error while executing script: ', what);
  HarnessFinish;
  Halt(3);
end;

procedure Run;
begin
  HarnessStart;
  HarnessWaitTick;
  HCycle := -1;
  MaskLikeSimTwo;
  try
    PS.ExecuteFunction([], 'Initialize');
  except
    on E: Exception do RunError(E.Message);
  end;
  Unmask;
  if PS.Exec.ExceptionCode <> erNoError then RunError(PS.ExecErrorToString);
  RecordSettings;
  ApplyOptions;
  RecordSettings;
  HN := StrToInt(HarnessOpt('cycles', '10'));
  for HK := 0 to HN - 1 do begin
    if HK > 0 then HarnessWaitTick;
    HCycle := HK;
    Host.ProgTime := HK * ScriptPeriod;
    HarnessRec(Format('CYCLE %d BEGIN', [HK]));
    HT0 := GetTickCount64;
    MaskLikeSimTwo;
    try
      if not PS.Execute then RunError(PS.ExecErrorToString);
    except
      on E: Exception do RunError(E.Message);
    end;
    Unmask;
    HarnessRec(Format('CYCLE %d END %d', [HK, GetTickCount64 - HT0]));
  end;
  HarnessFinish;
end;

begin
  if ParamCount < 2 then begin
    System.WriteLn('usage: pscript_harness compile|run SCRIPT [key=value ...]');
    Halt(2);
  end;
  Mode := ParamStr(1);
  ScriptFile := ParamStr(2);
  // SimTwo's start-up (Viewer.pas 4393): Format writes '.' whatever the Windows locale
  DefaultFormatSettings.DecimalSeparator := '.';
  Host := THost.Create(nil);
  Host.HUDStrings := TStringList.Create;
  Host.UDPDataRead := TMemoryStream.Create;
  PS := CreateEngine;
  if not CompileScript(ScriptFile) then Halt(1);
  if Mode = 'compile' then Halt(0);
  if Mode <> 'run' then begin
    System.WriteLn('unknown mode ', Mode);
    Halt(2);
  end;
  Run;
end.
