{ robotatfactory: a Linux stand-in for the Win32 `Windows` unit, only what SimTwo's units use of it.
  SimTwo names `Windows` in the uses clause of 14 units; on Linux FPC has no such unit. SimTwo.lpi finds this
  file through the search path platform/$(TargetOS), which exists only on Linux, so Windows builds are
  unchanged. Not part of SimTwo: shipped by robotatfactory (simtwo/linux/units/). }
unit Windows;

{$mode delphi}

interface

uses
  Classes, SysUtils, LCLType, LCLIntf;

type
  BOOL = LongBool;
  UINT = LongWord;
  DWORD = LongWord;
  THandle = System.THandle;

const
  INVALID_HANDLE_VALUE = THandle(-1);
  PAGE_READWRITE = $04;
  FILE_MAP_ALL_ACCESS = $F001F;
  MB_OK = LCLType.MB_OK;

  VK_LBUTTON = LCLType.VK_LBUTTON; VK_RBUTTON = LCLType.VK_RBUTTON; VK_CANCEL = LCLType.VK_CANCEL;
  VK_MBUTTON = LCLType.VK_MBUTTON; VK_BACK = LCLType.VK_BACK; VK_TAB = LCLType.VK_TAB;
  VK_CLEAR = LCLType.VK_CLEAR; VK_RETURN = LCLType.VK_RETURN; VK_SHIFT = LCLType.VK_SHIFT;
  VK_CONTROL = LCLType.VK_CONTROL; VK_MENU = LCLType.VK_MENU; VK_PAUSE = LCLType.VK_PAUSE;
  VK_CAPITAL = LCLType.VK_CAPITAL; VK_ESCAPE = LCLType.VK_ESCAPE; VK_SPACE = LCLType.VK_SPACE;
  VK_PRIOR = LCLType.VK_PRIOR; VK_NEXT = LCLType.VK_NEXT; VK_END = LCLType.VK_END; VK_HOME = LCLType.VK_HOME;
  VK_LEFT = LCLType.VK_LEFT; VK_UP = LCLType.VK_UP; VK_RIGHT = LCLType.VK_RIGHT; VK_DOWN = LCLType.VK_DOWN;
  VK_INSERT = LCLType.VK_INSERT; VK_DELETE = LCLType.VK_DELETE;
  VK_LSHIFT = LCLType.VK_LSHIFT; VK_RSHIFT = LCLType.VK_RSHIFT; VK_LCONTROL = LCLType.VK_LCONTROL;
  VK_RCONTROL = LCLType.VK_RCONTROL; VK_LMENU = LCLType.VK_LMENU; VK_RMENU = LCLType.VK_RMENU;
  DFC_BUTTON = LCLType.DFC_BUTTON; DFCS_BUTTONPUSH = LCLType.DFCS_BUTTONPUSH; DFCS_PUSHED = LCLType.DFCS_PUSHED;

function QueryPerformanceCounter(var Count: Int64): BOOL;
function QueryPerformanceFrequency(var Frequency: Int64): BOOL;
procedure ZeroMemory(Destination: Pointer; Length: PtrUInt);
procedure CopyMemory(Destination: Pointer; Source: Pointer; Length: PtrUInt);
function RGB(r, g, b: Byte): LongWord;
function GetLastError: DWORD;
function CloseHandle(hObject: THandle): BOOL;
procedure OutputDebugString(lpOutputString: PChar);
function CreateFileMapping(hFile: THandle; lpAttributes: Pointer; flProtect, dwMaximumSizeHigh,
  dwMaximumSizeLow: DWORD; lpName: PChar): THandle;
function MapViewOfFile(hFileMappingObject: THandle; dwDesiredAccess, dwFileOffsetHigh, dwFileOffsetLow: DWORD;
  dwNumberOfBytesToMap: PtrUInt): Pointer;
function UnmapViewOfFile(lpBaseAddress: Pointer): BOOL;
function DrawFrameControl(DC: HDC; const Rect: TRect; uType, uState: Cardinal): Boolean;

implementation

uses
  BaseUnix, Unix, Linux;

function QueryPerformanceCounter(var Count: Int64): BOOL;
var ts: TTimeSpec;
begin
  clock_gettime(CLOCK_MONOTONIC, @ts);
  Count := Int64(ts.tv_sec) * 1000000000 + ts.tv_nsec;
  Result := True;
end;

function QueryPerformanceFrequency(var Frequency: Int64): BOOL;
begin
  Frequency := 1000000000; // QueryPerformanceCounter counts nanoseconds
  Result := True;
end;

procedure ZeroMemory(Destination: Pointer; Length: PtrUInt);
begin
  FillChar(Destination^, Length, 0);
end;

procedure CopyMemory(Destination: Pointer; Source: Pointer; Length: PtrUInt);
begin
  Move(Source^, Destination^, Length);
end;

function RGB(r, g, b: Byte): LongWord;
begin
  Result := r or (g shl 8) or (b shl 16);
end;

function GetLastError: DWORD;
begin
  Result := fpgeterrno;
end;

function CloseHandle(hObject: THandle): BOOL;
begin
  Result := fpclose(hObject) = 0;
end;

procedure OutputDebugString(lpOutputString: PChar);
begin
  if IsConsole then writeln(StdErr, lpOutputString);
end;

{ Shared memory (SimTwo's camera via a named mapping): a file in /dev/shm, as Windows' named mappings are. }
var
  MapSize: PtrUInt = 0;

function CreateFileMapping(hFile: THandle; lpAttributes: Pointer; flProtect, dwMaximumSizeHigh,
  dwMaximumSizeLow: DWORD; lpName: PChar): THandle;
var fd: cint;
begin
  Result := 0;
  fd := fpopen('/dev/shm/' + string(lpName), O_RDWR or O_CREAT, &600);
  if fd < 0 then exit;
  MapSize := (PtrUInt(dwMaximumSizeHigh) shl 32) or dwMaximumSizeLow;
  if fpftruncate(fd, MapSize) <> 0 then begin
    fpclose(fd);
    exit;
  end;
  Result := fd;
end;

function MapViewOfFile(hFileMappingObject: THandle; dwDesiredAccess, dwFileOffsetHigh, dwFileOffsetLow: DWORD;
  dwNumberOfBytesToMap: PtrUInt): Pointer;
begin
  if dwNumberOfBytesToMap = 0 then dwNumberOfBytesToMap := MapSize;
  Result := fpmmap(nil, dwNumberOfBytesToMap, PROT_READ or PROT_WRITE, MAP_SHARED, hFileMappingObject, 0);
  if Result = MAP_FAILED then Result := nil;
end;

function UnmapViewOfFile(lpBaseAddress: Pointer): BOOL;
begin
  Result := fpmunmap(lpBaseAddress, MapSize) = 0;
end;

function DrawFrameControl(DC: HDC; const Rect: TRect; uType, uState: Cardinal): Boolean;
var R: TRect;
begin
  R := Rect;
  Result := LCLIntf.DrawFrameControl(DC, R, uType, uState);
end;

end.
