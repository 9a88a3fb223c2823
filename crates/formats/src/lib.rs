//! The files chromacal reads and writes for other tools, and the file handling under
//! them: ArgyllCMS CGATS measurement files (`cgats`, `.ti3`), colorimeter corrections
//! (`ccmx`, `ccss`), calibration curves (`cal`), ICC v4 and v2 display profiles
//! (`icc`, with the model's matrix/TRC and LUT tags in `matrix_trc` and `icc_lut`),
//! PsychoPy monitor files (`psychopy`), a monitor's EDID (`edid`), numeric CSV tables
//! (`numeric_csv`), stored time stamps (`time`), and files written whole or not at
//! all and read with a size limit (`durable`). Each format names the document it
//! follows.

pub mod cal;
pub mod ccmx;
pub mod ccss;
pub mod cgats;
pub mod child;
pub mod durable;
pub mod edid;
pub mod icc;
pub mod icc_lut;
pub mod matrix_trc;
pub mod numeric_csv;
pub mod psychopy;
pub mod time;
