//! Sequences of C ABI calls driven by the fuzzer's bytes: devices and filters created,
//! configured, committed, executed, retained and released in any order, with stale
//! handles, bad names, bad formats and garbage weights. Every sequence must end without a
//! crash or a memory error; only the images' extents are kept honest (a C caller that
//! lies about its buffer sizes is outside any API's protection).
#![no_main]
use std::ffi::CString;
use std::os::raw::c_void;

use libfuzzer_sys::fuzz_target;
use temc::capi::*;

const AE: &[u8] = include_bytes!("../../tests/data/models/ae_w0.0625.onnx");
const BUF_BYTES: usize = 24 * 24 * 16 * 2;

struct Bytes<'a>(&'a [u8], usize);

impl Bytes<'_> {
    fn u8(&mut self) -> Option<u8> {
        let b = *self.0.get(self.1)?;
        self.1 += 1;
        Some(b)
    }
    /// An element chosen by the next byte; `None` when the bytes or the slice are empty.
    fn pick<'b, T>(&mut self, v: &'b [T]) -> Option<&'b T> {
        let i = self.u8()? as usize;
        v.get(i % v.len().max(1))
    }
    fn i32(&mut self) -> Option<i32> {
        Some(i32::from_le_bytes([
            self.u8()?,
            self.u8()?,
            self.u8()?,
            self.u8()?,
        ]))
    }
}

unsafe extern "C" fn monitor(user: *mut c_void, _progress: f64) -> bool {
    let calls = &mut *(user as *mut u32);
    *calls += 1;
    *calls % 3 != 0
}

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data, 0);
    let mut devices: Vec<TEMCDevice> = Vec::new();
    let mut filters: Vec<TEMCFilter> = Vec::new();
    let mut input = vec![0.25f32; BUF_BYTES / 4];
    let mut output = vec![0f32; BUF_BYTES / 4];
    let mut calls = 0u32;
    let names: Vec<CString> = [
        "color",
        "albedo",
        "normal",
        "depth",
        "output",
        "weights",
        "hdr",
        "srgb",
        "cleanAux",
        "quality",
        "maxMemoryMB",
        "tileSize",
        "inputScale",
        "numThreads",
        "setAffinity",
        "verbose",
        "",
        "bogus",
    ]
    .iter()
    .map(|s| CString::new(*s).unwrap())
    .collect();
    let kinds: Vec<CString> = ["AE", "TEMC2", "DEMC", "RT", ""]
        .iter()
        .map(|s| CString::new(*s).unwrap())
        .collect();
    let formats = [
        TEMC_FORMAT_UNDEFINED,
        TEMC_FORMAT_FLOAT,
        TEMC_FORMAT_FLOAT2,
        TEMC_FORMAT_FLOAT3,
        TEMC_FORMAT_FLOAT4,
        TEMC_FORMAT_HALF,
        TEMC_FORMAT_HALF2,
        TEMC_FORMAT_HALF3,
        TEMC_FORMAT_HALF4,
        77,
    ];
    let null_dev: TEMCDevice = std::ptr::null_mut();
    for _ in 0..64 {
        let Some(op) = b.u8() else { break };
        let dev = |b: &mut Bytes| -> TEMCDevice { b.pick(&devices).copied().unwrap_or(null_dev) };
        let filt = |b: &mut Bytes| -> TEMCFilter {
            b.pick(&filters).copied().unwrap_or(std::ptr::null_mut())
        };
        let Some(name) = b.pick(&names).map(|n| n.as_ptr()) else {
            break;
        };
        // SAFETY: every pointer handed to the C ABI is NULL, a NUL-terminated name from
        // `names`/`kinds`, or a buffer of this function that outlives the filters using it.
        unsafe {
            match op % 18 {
                0 => devices.push(temcNewDevice((op / 18) as u32 % 3)),
                1 => temcCommitDevice(dev(&mut b)),
                2 => {
                    let v = b.i32().unwrap_or(0);
                    temcSetDeviceInt(dev(&mut b), name, v);
                }
                3 => {
                    let _ = temcGetDeviceInt(dev(&mut b), name);
                }
                4 => {
                    let Some(kind) = b.pick(&kinds).map(|k| k.as_ptr()) else {
                        break;
                    };
                    filters.push(temcNewFilter(dev(&mut b), kind));
                }
                5 => {
                    let (Some(&format), Some(w), Some(h), Some(off), Some(ps), Some(rs), Some(out)) = (
                        b.pick(&formats),
                        b.u8(),
                        b.u8(),
                        b.u8(),
                        b.u8(),
                        b.u8(),
                        b.u8(),
                    ) else {
                        break;
                    };
                    let (w, h) = (w as usize % 24, h as usize % 24);
                    let (off, ps, rs) =
                        (off as usize % 32, ps as usize % 40, (rs as usize % 8) * 64);
                    // The harness only describes memory it owns.
                    let px = if ps == 0 { 16 } else { ps.max(16) };
                    let row = if rs == 0 { px * w } else { rs.max(px * w) };
                    if off + h * row + px > BUF_BYTES {
                        continue;
                    }
                    let ptr = if out % 2 == 0 {
                        input.as_mut_ptr()
                    } else {
                        output.as_mut_ptr()
                    };
                    temcSetSharedFilterImage(
                        filt(&mut b),
                        name,
                        ptr as *mut c_void,
                        format,
                        w,
                        h,
                        off,
                        ps,
                        rs,
                    );
                }
                6 => temcUnsetFilterImage(filt(&mut b), name),
                7 => {
                    let Some(choice) = b.u8() else { break };
                    if choice % 2 == 0 {
                        temcSetSharedFilterData(
                            filt(&mut b),
                            name,
                            AE.as_ptr() as *mut c_void,
                            AE.len(),
                        );
                    } else {
                        let rest = &data[b.1.min(data.len())..];
                        let n = (choice as usize * 7).min(rest.len());
                        temcSetSharedFilterData(
                            filt(&mut b),
                            name,
                            rest.as_ptr() as *mut c_void,
                            n,
                        );
                    }
                }
                8 => temcUnsetFilterData(filt(&mut b), name),
                9 => {
                    let v = b.i32().unwrap_or(0);
                    let f = filt(&mut b);
                    match v & 3 {
                        0 => temcSetFilterBool(f, name, v & 4 != 0),
                        1 => temcSetFilterInt(f, name, v >> 2),
                        _ => temcSetFilterFloat(f, name, f32::from_bits(v as u32)),
                    }
                }
                10 => {
                    let f = filt(&mut b);
                    let _ = (
                        temcGetFilterBool(f, name),
                        temcGetFilterInt(f, name),
                        temcGetFilterFloat(f, name),
                    );
                }
                11 => temcCommitFilter(filt(&mut b)),
                12 => temcExecuteFilter(filt(&mut b)),
                13 => temcRetainFilter(filt(&mut b)),
                14 => temcReleaseFilter(filt(&mut b)),
                15 => temcRetainDevice(dev(&mut b)),
                16 => temcReleaseDevice(dev(&mut b)),
                _ => {
                    let f = filt(&mut b);
                    temcSetFilterProgressMonitorFunction(
                        f,
                        Some(monitor),
                        &mut calls as *mut u32 as *mut c_void,
                    );
                    let mut msg = std::ptr::null();
                    let _ = temcGetDeviceError(dev(&mut b), &mut msg);
                }
            }
        }
    }
    // Leave nothing alive: release every handle once more than the 64 calls could have
    // retained it (extra releases of dead handles are errors, not crashes). With 4
    // releases, retained devices outlived their input with their worker threads: RSS grew
    // to 1.8 GB over an hour and LeakSanitizer reported 772 workers at exit (2026-12-02).
    for f in &filters {
        for _ in 0..65 {
            temcReleaseFilter(*f);
        }
    }
    for d in &devices {
        for _ in 0..65 {
            temcReleaseDevice(*d);
        }
    }
    drop(output);
    drop(input);
});
