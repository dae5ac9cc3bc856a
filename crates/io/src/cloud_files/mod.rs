pub(crate) mod bucket_store;
pub mod las;
pub mod pcd;
pub mod ply;
pub(crate) mod point_rows;
pub mod scan_folder;
pub mod site_cloud;
